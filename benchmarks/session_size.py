"""Session file size per 1,000 frames: four tracked landmarks + a camera pose every frame.

Records the embedded demo (60 frames, 960x540) through the localisation pipeline three times —
without maps or frames, with the response, local-variation and spatial-weight maps, and with the
maps and the frames' JPEG files embedded (a pipeline recording's default) — and scales the file
sizes to 1,000 frames.

    python benchmarks/session_size.py
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

from autotrack.io.frames import open_frames
from autotrack.localization.scene import load_scene
from autotrack.params import preset
from autotrack.pipeline import Recording, localize_sequence

DEMO = Path(__file__).resolve().parents[1] / "static" / "demo"


def record(path: Path, **options: bool) -> int:
    """Record the demo's localisation run to `path`; returns the frame count."""
    scene = load_scene(DEMO / "scene.json")
    boxes = json.loads((DEMO / "boxes.json").read_text())
    recording = Recording(source=str(DEMO), path=path, scene_path=DEMO / "scene.json", **options)
    with open_frames(DEMO) as frames:
        outcomes = localize_sequence(
            frames, scene, boxes, preset("autotrack"), recording=recording, fps=10.0
        )
        return sum(1 for _ in outcomes)


def main() -> None:
    variants = {
        "boxes, signals, poses (record_maps=False, --no-frames)": {
            "record_maps": False,
            "embed_frames": False,
        },
        "+ response, local-variation and spatial-weight maps": {
            "record_maps": True,
            "embed_frames": False,
        },
        "+ maps + the demo's 960x540 JPEG files (default)": {
            "record_maps": True,
            "embed_frames": True,
        },
    }
    print("size per 1,000 frames, 4 targets + pose per frame (embedded demo):")
    with tempfile.TemporaryDirectory() as folder:
        for index, (label, options) in enumerate(variants.items()):
            path = Path(folder) / f"session{index}.mcap"
            frames = record(path, **options)
            per_thousand = path.stat().st_size * 1000 / frames / 1e6
            print(f"  {label:<62} {per_thousand:8.2f} MB")


if __name__ == "__main__":
    main()
