"""The tracker's features written channel-first and windowed in the kernels' own pass
(`features.feature_maps`, `scale_features` with weights) equal the channel-last features times
the window bit for bit, on search patches and scale samples of real sequences."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from autotrack import AutoTrack, preset
from autotrack.errors import InputError
from autotrack.evaluation.datasets import load_otb_sequence
from autotrack.io.frames import read_image
from autotrack.params import TrackerParams
from autotrack.tracker.backend.fast_features import (
    colour_table_feature,
    feature_maps,
    grey_feature,
    scale_features,
)
from autotrack.tracker.backend.fast_fhog import fhog
from autotrack.tracker.backend.fast_sampling import sized_patches
from autotrack.tracker.features import lab11_table, load_colour_table
from autotrack.tracker.sampling import scale_sizes
from tests.conftest import COLOUR_TABLE, needs_colour_table, shared_sequence_dir


def scale_patches(image, position, base_target_size_hw, factors, model_size_hw):
    """The scale samples of `factors` (the scale filter's `sized_patches(scale_sizes(...))`)."""
    sizes = scale_sizes(base_target_size_hw, factors)
    return sized_patches(image, position, sizes, model_size_hw)


CASES = (("DTB70", "Surfing06"), ("UAV123_10fps", "boat5"), ("OTB", "Dog1"))
"""Colour frames (a small and a large target) and a grey one."""


def channel_last_stack(patch: np.ndarray, params: TrackerParams, table) -> np.ndarray:
    """The stack as the component features concatenated channel-last (the path before round 8)."""
    parts = [grey_feature(patch, 4), fhog(patch)[:, :, :31]]
    if patch.ndim == 3:
        parts.append(colour_table_feature(patch, table if table is not None else lab11_table(), 4))
    return np.concatenate(parts, axis=2)


def tracked_frames(dataset: str, name: str, params: TrackerParams, count: int = 6):
    """(tracker, frame) after each of the first `count` updates of a real sequence."""
    sequence = load_otb_sequence(shared_sequence_dir(dataset, name))[0]
    tracker = AutoTrack(params)
    frames = [read_image(path, i) for i, path in enumerate(sequence.frame_paths[: count + 1])]
    tracker.init(frames[0], sequence.init_box)
    for frame in frames[1:]:
        tracker.update(frame)
        yield tracker, tracker._prepare(frame)


@needs_colour_table
@pytest.mark.parametrize(("dataset", "name"), CASES)
@pytest.mark.parametrize("colour", ["table", "lab11"])
def test_windowed_maps_in_the_transform_buffer_equal_the_old_product(dataset, name, colour):
    params = preset("autotrack", str(COLOUR_TABLE) if colour == "table" else None)
    table = load_colour_table(COLOUR_TABLE) if colour == "table" else None
    for tracker, image in tracked_frames(dataset, name, params):
        patch = tracker._search_patch(image)
        expected = channel_last_stack(patch, params, table).transpose(2, 0, 1) * tracker.cos_window
        buffer = tracker.backend.transform.input_maps
        written = feature_maps(patch, params, table, tracker.cos_window, out=buffer)
        assert written is buffer
        assert written.tobytes() == expected.tobytes()
        spectrum = tracker.backend.transform.forward(buffer).copy()
        assert spectrum.tobytes() == tracker.backend.transform.forward(expected.copy()).tobytes()
        assert (
            feature_maps(patch, params, table).tobytes()
            == np.ascontiguousarray(
                channel_last_stack(patch, params, table).transpose(2, 0, 1)
            ).tobytes()
        )


@needs_colour_table
@pytest.mark.parametrize(("dataset", "name"), CASES)
def test_weighted_scale_samples_equal_the_samples_times_the_window(dataset, name):
    params = preset("autotrack", str(COLOUR_TABLE))
    for tracker, image in tracked_frames(dataset, name, params, count=4):
        scales = tracker.scale_filter
        patches = scale_patches(
            image,
            tracker.position,
            scales.base_target_size_hw,
            tracker.scale * scales.scale_steps,
            scales.model_size_hw,
        )
        old = np.stack([fhog(patch)[:, :, :31].reshape(-1) for patch in patches])
        expected = old * scales.window[:, None]
        assert scale_features(patches).tobytes() == old.tobytes()
        assert scale_features(patches, scales.window).tobytes() == expected.tobytes()
        indices = np.arange(len(patches))
        extracted = scales._extract(image, tracker.position, tracker.scale, indices)
        assert extracted.tobytes() == expected.tobytes()


def test_feature_maps_refuse_a_wrong_window_or_buffer():
    patch = np.random.default_rng(3).integers(0, 256, (40, 36, 3)).astype(np.uint8)
    params = TrackerParams()
    with pytest.raises(InputError, match="window must be float32"):
        feature_maps(patch, params, None, np.ones((10, 9)))
    with pytest.raises(InputError, match="buffer"):
        feature_maps(patch, params, None, out=np.empty((42, 9, 10), np.float32))
    hog_only = dataclasses.replace(params, use_grey=False, colour_feature="none")
    window = np.random.default_rng(4).random((10, 9)).astype(np.float32)
    maps = feature_maps(patch, hog_only, None, window)
    assert maps.tobytes() == (fhog(patch)[:, :, :31].transpose(2, 0, 1) * window).tobytes()
    with pytest.raises(InputError, match="sample weights"):
        scale_features(np.zeros((3, 16, 16), np.uint8), np.ones(2, np.float32))
