"""Could the 33 scale samples come from one resize of the largest patch? No: measured here.

The release resamples each of the 33 DSST scale samples on its own: a crop of the target at
that scale, area-averaged (INTER_AREA) down to the scale model's size. The cheaper scheme
tried here resizes the largest crop once (to the model size times the largest / smallest
sample ratio) and cuts every sample from that image, centred, then resizes it to the model
size. Each faithful sample is an area average over the original pixels with its own tap
table; the cheaper one averages pixels that were already averaged and rounded to uint8 on
another grid, so the samples differ. Printed per sequence (third frame, the tracker's own
position and scale): the share of differing sample pixels and the mean / max difference.

    python benchmarks/scale_samples_shared.py
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from autotrack import AutoTrack, preset
from autotrack.evaluation.datasets import load_otb_sequence
from autotrack.io.frames import read_image
from autotrack.tracker import sampling

SHARED = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
COLOUR_TABLE = SHARED / "color_names" / "cn_norm_32768x10.npy"
SEQUENCES = ("DTB70/Surfing06", "UAV123_10fps/boat5", "OTB/Crossing", "VOT2015/bag")


def samples_from_one_resize(image, position, sizes, model_hw) -> np.ndarray:
    """Every sample cut from one INTER_AREA resize of the largest crop, then resized."""
    largest = sizes[np.argmax(sizes.prod(axis=1))]
    smallest = sizes[np.argmin(sizes.prod(axis=1))]
    rows = int(round(model_hw[0] * largest[0] / smallest[0]))
    cols = int(round(model_hw[1] * largest[1] / smallest[1]))
    crop = sampling.crop_replicate(image, position, (int(largest[0]), int(largest[1])))
    large = cv2.resize(crop, (cols, rows), interpolation=cv2.INTER_AREA)
    samples = []
    for size in sizes:
        height = max(int(round(rows * size[0] / largest[0])), 1)
        width = max(int(round(cols * size[1] / largest[1])), 1)
        top, left = (rows - height) // 2, (cols - width) // 2
        cut = large[top : top + height, left : left + width]
        samples.append(sampling.resize_auto(cut, model_hw))
    return np.array(samples)


def main() -> None:
    cv2.setNumThreads(1)
    for name in SEQUENCES:
        sequence = load_otb_sequence(SHARED / "sequences" / name)[0]
        frames = [read_image(path) for path in sequence.frame_paths[:3]]
        tracker = AutoTrack(preset("autotrack", str(COLOUR_TABLE)))
        tracker.init(frames[0], sequence.init_box)
        tracker.update(frames[1])
        scale_filter = tracker.scale_filter
        factors = tracker.scale * scale_filter.scale_steps
        base = scale_filter.base_target_size_hw
        model = scale_filter.model_size_hw
        faithful = sampling.scale_patches(frames[2], tracker.position, base, factors, model)
        sizes = np.maximum(np.floor(base[None, :] * factors[:, None]), 2).astype(np.int64)
        cheaper = samples_from_one_resize(frames[2], tracker.position, sizes, model)
        difference = np.abs(cheaper.astype(np.int64) - faithful.astype(np.int64))
        print(
            f"{sequence.name:14s} samples {sizes[0][0]}x{sizes[0][1]}..{sizes[-1][0]}x"
            f"{sizes[-1][1]} -> {model[0]}x{model[1]}: {np.mean(difference > 0):.0%} of the "
            f"pixels differ, mean |d| {difference.mean():.2f}, max |d| {difference.max()}"
        )


if __name__ == "__main__":
    main()
