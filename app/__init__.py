"""AutoTrack Studio, the browser app: thin viser wiring over the `autotrack` library.

Start it with `autotrack app`, or from Python:

>>> from app.server import AppConfig, StudioServer
>>> studio = StudioServer(AppConfig(port=8080))   # doctest: +SKIP
>>> print(studio.url)                              # doctest: +SKIP

Modules: `server` (the viser server and the state tabs share), `tab` (one browser tab's GUI
and threads), `run` (targets, trackers, results, poses and recording of one tab), `canvas`
(letterboxing and overlays), `view3d` (3-D scene), `plots` (live charts), `paths` (what a
browser may open; safe uploads), `exports` (downloads), `channel` (the per-tab connection).
"""
