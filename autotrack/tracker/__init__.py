"""The AutoTrack tracker. The reference algorithm at this level, in numpy / scipy.fft / OpenCV:
features (`features`, `fhog`, `colour_terms`), patches (`sampling`), the DCF solved by ADMM
(`dcf`), the automatic spatio-temporal regularisation with eq. 13 (`regularization`), the DSST
scale filter (`scale`) and the tracker that orchestrates them (`tracker`). `backend/`: where a
frame's maths runs (the reference, or its numba twins); `plus/`: autotrack+; `parallel/`:
several targets on threads or child processes."""

# autotrack+ is a subclass the faithful tracker makes for parameters beyond the release: loaded
# with the package so that `AutoTrack(preset("autotrack+"))` finds it (tracker.py stays the
# paper's, importing nothing of autotrack+).
from autotrack.tracker.plus import tracker as _plus_tracker  # noqa: E402, F401
