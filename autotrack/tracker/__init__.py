"""The AutoTrack tracker: features (grey, fHOG, colour), the DCF solved by ADMM (`dcf`), the
automatic spatio-temporal regularisation with eq. 13 (`regularization`), the DSST scale filter
(`scale`), patch sampling, the tracker that orchestrates them and several targets at once
(`multi`); the opt-in autotrack+ mechanisms (`robust`, `redetect`)."""
