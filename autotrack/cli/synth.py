"""`autotrack synth`: render the synthetic localisation test bed, or the app's embedded demo."""

from __future__ import annotations

import argparse
from pathlib import Path

from tqdm import tqdm

from autotrack.errors import InputError


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "synth",
        help="render the synthetic localisation test bed (sequences with exact ground truth)",
        description=(
            "Render synthetic indoor sequences like the paper's localisation experiment: four "
            "landmarks, a moving 1280x720 camera at 10 fps, lighting changes, noise and motion "
            "blur, with exact camera poses, intrinsics and landmark boxes. Each sequence gets a "
            "folder OUT_DIR/<name>/ with img/, scene.json, boxes.json, poses_gt.tum, "
            "groundtruth/<landmark>.txt and sequence.json."
        ),
    )
    parser.add_argument("out_dir", type=Path, help="folder to write the sequences into")
    parser.add_argument("--sequences", type=int, default=6, help="how many (default 6)")
    parser.add_argument(
        "--frames",
        type=int,
        default=None,
        help="frames per sequence (default: the paper's 652, 431, 400, 381, 352, 450)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of everything random")
    parser.add_argument(
        "--width", type=int, default=1280, help="image width, 16:9 (default 1280, as the paper)"
    )
    parser.add_argument("--jpeg-quality", type=int, default=90, help="JPEG quality (default 90)")
    parser.add_argument(
        "--demo",
        action="store_true",
        help=(
            "write the app's embedded demo instead: one short sequence straight into OUT_DIR "
            "(60 frames, 960x540, JPEG quality 60)"
        ),
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(func=run_synth)


def run_synth(args: argparse.Namespace) -> int:
    from autotrack.synthetic.testbed import generate_demo, generate_test_bed, sequence_specs
    from autotrack.synthetic.trajectories import RenderSettings

    if args.width < 64 or args.width % 16:
        raise InputError("--width must be a multiple of 16, at least 64 (16:9 images)")
    if not 1 <= args.jpeg_quality <= 100:
        raise InputError("--jpeg-quality must be between 1 and 100")
    if args.demo:
        spec = generate_demo(args.out_dir, seed=args.seed)
        print(f"demo written to {args.out_dir} ({spec.frames} frames, {spec.trajectory})")
        return 0
    settings = RenderSettings(
        width=args.width, height=args.width * 9 // 16, jpeg_quality=args.jpeg_quality
    )
    specs = sequence_specs(args.sequences, args.frames, args.seed, settings)
    total = sum(spec.frames for spec in specs)
    with tqdm(total=total, unit="frame", desc="rendering", disable=args.quiet) as progress:
        folders = generate_test_bed(args.out_dir, specs, progress.update)
    for folder, spec in zip(folders, specs, strict=True):
        print(f"{folder}  {spec.trajectory}  {spec.frames} frames")
    return 0
