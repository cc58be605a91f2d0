"""`autotrack localize` keeps a run's outcomes as columns (`OutcomeLog`): the report reads the
same boxes, scores, points and poses as from the `FrameOutcome`s it used to keep."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from autotrack.io.frames import open_frames
from autotrack.localization.reacquire import ReacquireParams
from autotrack.localization.refine import RefineParams
from autotrack.localization.scene import load_scene
from autotrack.params import preset
from autotrack.pipeline import localize_sequence
from autotrack.pipeline.outcomes import OutcomeLog

DEMO = Path(__file__).resolve().parents[1] / "static" / "demo"
FRAMES = 20


def test_the_log_answers_as_the_outcomes_did_past_its_initial_capacity() -> None:
    scene = load_scene(DEMO / "scene.json")
    boxes = json.loads((DEMO / "boxes.json").read_text())
    with open_frames(DEMO / "img") as frames:
        outcomes = localize_sequence(
            frames,
            scene,
            boxes,
            preset("autotrack"),
            refine_params=RefineParams(),
            reacquire_params=ReacquireParams(),
            map_window=0,
        )
        log = OutcomeLog(scene.landmark_ids, capacity=3)
        kept = []
        for outcome in outcomes:
            log.append(outcome)
            kept.append(outcome)
            if outcome.frame_index == FRAMES - 1:
                break
    assert len(log) == FRAMES and log.frame_indices.tolist() == list(range(FRAMES))
    assert all(p is o.pose for p, o in zip(log.poses, kept, strict=True))
    assert sum(pose.valid for pose in log.poses) > FRAMES // 2  # a run worth checking
    for row, outcome in enumerate(kept):
        tracks = outcome.landmark_tracks
        for landmark_id in scene.landmark_ids:
            result = tracks.get(landmark_id)
            got = log.track(row, landmark_id)
            if result is None:
                assert got is None
                continue
            box, peak, aberrant = got
            assert box == result.box and aberrant == result.aberrant
            np.testing.assert_equal(peak, result.peak_score)  # NaN on the first frame
        assert log.image_points(row) == outcome.image_points
        assert log.refined(row) == outcome.refined and log.events(row) == outcome.events
    # Without solver inputs, the points are the boxes' centres, as FrameOutcome's.
    log.solver_inputs[1] = None
    expected = {k: r.center for k, r in kept[1].landmark_tracks.items()}
    assert log.image_points(1) == expected and log.refined(1) == {}
