"""The AutoTrack tracker. The reference algorithm at this level, in numpy / scipy.fft / OpenCV:
features (`features`, `fhog`, `colour_terms`), patches (`sampling`), the DCF solved by ADMM
(`dcf`), the automatic spatio-temporal regularisation with eq. 13 (`regularization`), the DSST
scale filter (`scale`) and the tracker that orchestrates them (`tracker`). `backend/`: where a
frame's maths runs (the reference, or its numba twins); `plus/`: autotrack+; `parallel/`:
several targets on threads or child processes."""
