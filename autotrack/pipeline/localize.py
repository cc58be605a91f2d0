"""Localisation over a whole sequence: the pipeline with every landmark boxed on the first frame."""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence

import numpy as np

from autotrack.io.frames import FrameSource, InMemoryFrames
from autotrack.localization.localizer import LocalizerParams
from autotrack.localization.pnp import boxes_by_landmark
from autotrack.localization.reacquire import ReacquireParams
from autotrack.localization.refine import RefineParams
from autotrack.localization.scene import Scene
from autotrack.params import TrackerParams
from autotrack.pipeline.pipeline import Pipeline
from autotrack.pipeline.recording import Recording
from autotrack.pipeline.targets import FrameOutcome
from autotrack.tracker.parallel.target_process import WorkerPool

Box = tuple[float, float, float, float]


def localize_sequence(
    frames: FrameSource | Sequence[np.ndarray],
    scene: Scene,
    init_boxes: Mapping[str, Box] | Sequence[Box],
    tracker_params: TrackerParams,
    localizer_params: LocalizerParams | None = None,
    *,
    tracker: str | None = None,
    recording: Recording | None = None,
    fps: float | None = None,
    threads: int = 1,
    processes: int = 1,
    worker_pool: WorkerPool | None = None,
    refine_params: RefineParams | None = None,
    reacquire_params: ReacquireParams | None = None,
    map_window: int = 1,
) -> Iterator[FrameOutcome]:
    """Track every landmark and estimate the camera pose frame by frame.

    `frames` is a FrameSource or a list of RGB frames. `init_boxes` gives the first frame's
    boxes (x, y, w, h, 0-based pixels): landmark id -> box, or a list of boxes whose landmarks
    the correspondence search finds on the first frame (boxes.json's two forms). `tracker`:
    `nanotrack` or `hybrid` to track with them (the Pipeline's; None: AutoTrack).
    `refine_params` turns on the sub-pixel refinement of the landmark points
    (`localization.refine`), `reacquire_params` the out-of-view gate and re-acquisition of lost
    landmarks (`localization.reacquire`; it uses the refiner's templates, so it turns refinement
    on with default settings if needed). `threads` and `processes` run the landmarks'
    trackers concurrently (the Pipeline's `tracker_threads`, `tracker_processes`; `worker_pool`
    lends the child processes, None: the run's own).
    `map_window` (the Pipeline's): 1 keeps the maps of
    the frame yielded only, 0 none.
    """
    if not isinstance(frames, FrameSource):
        frames = InMemoryFrames(list(frames), name="frames")
    boxes = boxes_by_landmark(init_boxes, scene)
    with Pipeline(
        frames,
        tracker_params,
        tracker=tracker,
        scene=scene,
        localizer_params=localizer_params,
        recording=recording,
        fps=fps,
        tracker_threads=threads,
        tracker_processes=processes,
        worker_pool=worker_pool,
        refine_params=refine_params,
        reacquire_params=reacquire_params,
        map_window=map_window,
    ) as pipeline:
        pipeline.add_targets(0, boxes)
        yield from pipeline.run()
