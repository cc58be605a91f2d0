"""AutoTrack Studio, the browser app: thin viser wiring over the `autotrack` library.

Start it with `autotrack app`, or from Python:

>>> from autotrack_studio.config import AppConfig
>>> from autotrack_studio.server import StudioServer
>>> studio = StudioServer(AppConfig(port=8080))   # doctest: +SKIP
>>> print(studio.url)                              # doctest: +SKIP

Modules, from the server down (docs/app.md, "How the app is built"):
`cli` (`autotrack app`), `config` (how the server was started), `server` (the viser server,
one `Tab` per browser tab), `recordings` (the session files tabs are writing: the only run-time
state tabs share), `tab` (a tab's widgets wired to its controller), `panels` (the `gui.add_*`
calls), `controller` (the per-tab state and commands; no viser), `worker` (the thread that runs
commands and playback), `display` (the thread that sends frames, plots, maps and the 3-D view),
`views` (the snapshots passed between them), `canvas` (letterboxing and overlays), `view3d`
(3-D scene), `plots` (live charts), `paths` (what a browser may open; safe uploads), `exports`
(downloads), `channel` (the per-tab connection), `access` (token, Origin and Host checks),
`uploads` (uploads streamed to disk within the limits), `owners` (whose sessions and uploads a
browser sees). Tracking, poses and recording are the
library's `autotrack.pipeline.Pipeline`.
"""
