"""Live input through the pipeline: the newest frame each time the pipeline is free.

`run_live` takes frames from a `LiveLog` (`autotrack.io.live`), shows them to a `Pipeline` as a
growing `LiveFrames` source indexed by capture index, and yields each processed frame with its
outcome. Results, poses and the session recording therefore name frames as the source counted
them, the dropped frames are simply never tracked, and the latency of a frame runs from its
capture to the pipeline's result (tracking, pose and recording).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np

from autotrack.io.live import (
    CapturedFrame,
    LiveFrames,
    LiveLog,
    LiveReader,
    LiveSummary,
    describe_source,
)
from autotrack.localization.localizer import LocalizerParams
from autotrack.localization.scene import Scene
from autotrack.params import TrackerParams
from autotrack.pipeline.pipeline import Pipeline
from autotrack.pipeline.recording import Recording
from autotrack.pipeline.targets import FrameOutcome

Box = tuple[float, float, float, float]


def run_live(
    log: LiveLog,
    params: TrackerParams,
    start: Callable[[Pipeline, int], object],
    *,
    tracker: str | None = None,
    scene: Scene | None = None,
    localizer_params: LocalizerParams | None = None,
    recording: Recording | None = None,
    fps: float | None = None,
    threads: int = 1,
    **pose_options: Any,
) -> Iterator[tuple[CapturedFrame, FrameOutcome]]:
    """Each processed frame and its outcome, until the source ends.

    `start(pipeline, frame_index)` adds the targets on the first frame; `tracker` is the
    Pipeline's (None: AutoTrack with `params`). `fps` is the frame
    rate of the recording's log times (default: the reader's). The reader must be started.
    `pose_options` go to the Pipeline (refine_params, reacquire_params, map_window).
    """
    frames = LiveFrames(describe_source(log.reader.source), fps or log.reader.fps)
    taken = log.frames()
    first = next(taken, None)
    if first is None:
        return
    frames.take(first)
    pipeline = Pipeline(
        frames,
        params,
        tracker=tracker,
        scene=scene,
        localizer_params=localizer_params,
        recording=recording,
        fps=fps,
        tracker_threads=threads,
        **pose_options,
    )
    try:
        start(pipeline, first.index)
        yield log.result_ready(), pipeline.outcome(first.index)
        yield from follow_live(log, pipeline, frames, taken)
    finally:
        frames.close()
        pipeline.close()


def follow_live(
    log: LiveLog,
    pipeline: Pipeline,
    frames: LiveFrames,
    taken: Iterator[CapturedFrame] | None = None,
) -> Iterator[tuple[CapturedFrame, FrameOutcome]]:
    """Advance a pipeline whose targets are already placed (on `frames`' last taken frame)
    over the newest frame each time it is free; each processed frame and its outcome, until
    the source ends. `taken`: the frames to use (default `log.frames()`). Closing the
    iterator leaves the pipeline, the frames and the reader to their owner."""
    for frame in log.frames() if taken is None else taken:
        frames.take(frame)
        pipeline.advance(frame.index)
        outcome = pipeline.outcome(frame.index)
        yield log.result_ready(), outcome


def track_live(
    reader: LiveReader,
    params: TrackerParams,
    init_box: Sequence[float],
    on_result: Callable[[CapturedFrame, FrameOutcome], None] | None = None,
    tracker: str | None = None,
) -> tuple[np.ndarray, LiveSummary]:
    """Track one target on the newest frame each time the pipeline is free (`tracker`: the
    Pipeline's, None: AutoTrack with `params`).

    Returns (captured frames, 4) 0-based boxes, NaN rows for dropped frames, and the summary.
    The reader must be started.
    """
    log = LiveLog(reader)
    targets: list[str] = []

    def start(pipeline: Pipeline, frame_index: int) -> None:
        box = tuple(float(v) for v in init_box)
        targets.append(pipeline.add_target(frame_index, box, landmark_id=None))

    boxes: dict[int, tuple[float, float, float, float]] = {}
    for frame, outcome in run_live(log, params, start, tracker=tracker, map_window=0):
        boxes[frame.index] = outcome.tracks[targets[0]].box
        if on_result is not None:
            on_result(frame, outcome)
    summary = log.summary()
    array = np.full((summary.captured, 4), np.nan)
    for index, box in boxes.items():
        array[index] = box
    return array, summary


def warm_up(
    params: TrackerParams,
    frame_size: tuple[int, int] | None,
    boxes: Sequence[Sequence[float]],
    tracker_name: str | None = None,
) -> None:
    """Run a throwaway tracker (`tracker_name`, None: AutoTrack of `params`) on a noise frame
    of the source's size from each box, so that loading the compiled kernels and planning the
    FFTs happen before the first live frame (otherwise the first frames are dropped while they
    do)."""
    from autotrack.hybrid.factory import make_tracker

    if frame_size is None:
        return
    width, height = frame_size
    frame = np.random.default_rng(0).integers(0, 256, (height, width, 3), dtype=np.uint8)
    for box in boxes:
        tracker = make_tracker(tracker_name or params.name, params)
        tracker.init(frame, box)
        tracker.update(frame)
