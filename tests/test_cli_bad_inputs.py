"""Bad inputs end in one line on stderr and exit code 2, before any work, with nothing
clobbered (issue 17)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import pytest

from tests.sequences import moving_target_sequence

REPO = Path(__file__).resolve().parents[1]
DEMO = REPO / "static" / "demo"
SENTINEL = b"precious results\n"


@pytest.fixture(scope="module")
def workspace(tmp_path_factory) -> Path:
    """A sequence, the demo's scene and boxes, files that must not be clobbered, bad files."""
    root = tmp_path_factory.mktemp("bad")
    frames = moving_target_sequence(num_frames=5).frames
    (root / "seq").mkdir()
    for index, frame in enumerate(frames, start=1):
        cv2.imwrite(str(root / "seq" / f"{index:04d}.png"), frame)
    shutil.copytree(DEMO, root / "demo")
    (root / "existing.txt").write_bytes(SENTINEL)
    (root / "readonly").mkdir()
    (root / "readonly").chmod(0o555)
    (root / "not_utf8.json").write_bytes(b'{"T1": [1, 2, 3, 4], "\xff\xfe": 1}')
    (root / "nested.json").write_text("[" * 100_000 + "]" * 100_000)
    (root / "synth_out").write_bytes(SENTINEL)
    (root / "nonempty").mkdir()
    (root / "nonempty" / "keep.txt").write_bytes(SENTINEL)
    boxes = json.loads((DEMO / "boxes.json").read_text())
    boxes["A\nX"] = boxes.pop("A")
    (root / "newline_boxes.json").write_text(json.dumps(boxes))
    scene = json.loads((DEMO / "scene.json").read_text())
    scene["landmarks"][0]["id"] = "A\u0000"
    (root / "nul_scene.json").write_text(json.dumps(scene))
    return root


CASES = {
    # output paths, checked before any frame is tracked
    "track --out existing": ["track", "seq", "--init", "1,1,9,9", "--out", "existing.txt"],
    "track --out folder": ["track", "seq", "--init", "1,1,9,9", "--out", "seq"],
    "track --out read-only": ["track", "seq", "--init", "1,1,9,9", "--out", "readonly/b.txt"],
    "track --out under a file": ["track", "seq", "--init", "1,1,9,9", "--out", "existing.txt/b"],
    "localize --out existing": ["localize", "demo", "--out", "existing.txt"],
    "localize --tracks existing": ["localize", "demo", "--tracks", "existing.txt"],
    "localize --session existing": ["localize", "demo", "--session", "existing.txt"],
    "bench --json existing": ["bench", "seq", "--json", "existing.txt"],
    "synth OUT a file": ["synth", "synth_out"],
    "synth OUT not empty": ["synth", "nonempty", "--frames", "2", "--sequences", "1"],
    "synth --demo OUT not empty": ["synth", "nonempty", "--demo"],
    # numeric options
    "localize --fps nan": ["localize", "demo", "--fps", "nan"],
    "localize --fps inf": ["localize", "demo", "--fps", "inf"],
    "localize --fps 0": ["localize", "demo", "--fps", "0"],
    "localize --fps -5": ["localize", "demo", "--fps", "-5"],
    "localize --max-rms nan": ["localize", "demo", "--max-rms", "nan"],
    "localize --processes 0": ["localize", "demo", "--processes", "0"],
    "synth --seed -1": ["synth", "fresh", "--seed", "-1"],
    # unreadable inputs
    "localize --init not UTF-8": ["localize", "demo", "--init", "not_utf8.json"],
    "localize --init deeply nested": ["localize", "demo", "--init", "nested.json"],
    "localize --scene not UTF-8": ["localize", "demo", "--scene", "not_utf8.json"],
    "localize --scene deeply nested": ["localize", "demo", "--scene", "nested.json"],
    "localize --gt not UTF-8": ["localize", "demo", "--gt", "not_utf8.json"],
    "session info not UTF-8": ["session", "info", "not_utf8.json"],
    # identifiers with control characters, refused before any file is created
    "localize --init newline in an id": ["localize", "demo", "--init", "newline_boxes.json"]
    + ["--session", "new.mcap"],
    "localize --scene NUL in an id": ["localize", "demo", "--scene", "nul_scene.json"]
    + ["--session", "new.mcap"],
    # the app, before it serves
    "app --sessions under a file": ["app", "--sessions", "existing.txt/sessions", "--port", "0"],
    "app --host unknown name": ["app", "--host", "no-such-host.invalid", "--port", "0"],
}


QUIET = {
    "track": ["--quiet"],
    "localize": ["--quiet"],
    "synth": ["--quiet"],
    "bench": ["--no-progress"],
}


def _snapshot(root: Path) -> dict[str, bytes]:
    return {
        str(path.relative_to(root)): path.read_bytes()
        for path in sorted(root.rglob("*"))
        if path.is_file() and os.access(path, os.R_OK)
    }


@pytest.mark.parametrize("argv", CASES.values(), ids=CASES.keys())
def test_bad_input_ends_in_one_line_and_exit_2(workspace: Path, argv: list[str]) -> None:
    if os.geteuid() == 0 and "readonly/b.txt" in argv:
        pytest.skip("root may write into read-only folders")
    before = _snapshot(workspace)
    done = subprocess.run(
        [sys.executable, "-m", "autotrack.cli", *argv, *QUIET.get(argv[0], [])],
        cwd=workspace,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("autotrack: error: "), done.stderr
    assert _snapshot(workspace) == before
    assert not (workspace / "fresh").exists()


@pytest.mark.parametrize(
    ("field", "value"), [("fx", 1e-300), ("cx", 1e308), ("distortion", [1e6, 0, 0, 0, 0])]
)
def test_absurd_intrinsics_are_refused(workspace: Path, tmp_path: Path, field, value) -> None:
    scene = json.loads((DEMO / "scene.json").read_text())
    scene["camera"][field] = value
    (tmp_path / "scene.json").write_text(json.dumps(scene))
    done = subprocess.run(
        [sys.executable, "-m", "autotrack.cli", "localize", "demo", "--quiet"]
        + ["--scene", str(tmp_path / "scene.json")],
        cwd=workspace,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 2 and f"camera.{field}" in done.stderr, done.stderr
    assert done.stderr.count("\n") == 1


def test_a_run_without_any_valid_pose_warns(workspace: Path, tmp_path: Path) -> None:
    scene = json.loads((DEMO / "scene.json").read_text())
    # Plausible intrinsics, but far from the demo camera's: no pose passes the checks.
    scene["camera"]["fx"] = scene["camera"]["fy"] = 5.0
    (tmp_path / "scene.json").write_text(json.dumps(scene))
    done = subprocess.run(
        [sys.executable, "-m", "autotrack.cli", "localize", "demo", "--quiet"]
        + ["--scene", str(tmp_path / "scene.json")],
        cwd=workspace,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert "no frame got a valid pose" in done.stderr, done.stderr


def test_a_read_only_output_is_refused_before_any_work(tmp_path: Path, monkeypatch) -> None:
    """As root every folder is writable, so the permission answer is injected."""
    from autotrack.cli import checks
    from autotrack.errors import InputError

    monkeypatch.setattr(checks.os, "access", lambda path, mode: False)
    with pytest.raises(InputError, match="permission denied"):
        checks.check_output_file(tmp_path / "new.txt", "--out", force=False)
    (tmp_path / "old.txt").write_bytes(SENTINEL)
    with pytest.raises(InputError, match="cannot be written"):
        checks.check_output_file(tmp_path / "old.txt", "--out", force=True)


def test_a_full_disk_at_the_end_ends_in_one_line(workspace: Path, monkeypatch, capsys) -> None:
    import errno

    from autotrack.cli import main, track

    def full_disk(path, boxes) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(track, "write_boxes", full_disk)
    out = workspace / "full" / "boxes.txt"
    argv = ["track", str(workspace / "seq"), "--init", "1,1,9,9", "--out", str(out), "--quiet"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err == f"autotrack: error: {out}: No space left on device\n"


@pytest.mark.parametrize(
    "option", [["--init", "newline_boxes.json"], ["--scene", "nul_scene.json"]], ids=str
)
def test_control_characters_in_ids_are_refused_as_the_file_is_read(
    workspace: Path, option: list[str]
) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "autotrack.cli", "localize", "demo", "--quiet", *option]
        + ["--session", "new.mcap"],
        cwd=workspace,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 2 and "holds a control character" in done.stderr, done.stderr
    assert done.stderr.count("\n") == 1 and option[1] in done.stderr
    assert not (workspace / "new.mcap").exists()


def _occupy(first: int, count: int) -> list:
    """Listening sockets on 127.0.0.1 ports first..first+count-1 (empty if one is taken)."""
    import socket

    held = []
    try:
        for port in range(first, first + count):
            listener = socket.socket()
            held.append(listener)
            listener.bind(("127.0.0.1", port))
            listener.listen()
    except OSError:
        for listener in held:
            listener.close()
        return []
    return held


@pytest.mark.parametrize("where", ["a block of ports", "the top of the range"])
def test_app_with_every_port_taken_ends_in_one_line(workspace: Path, where: str) -> None:
    """viser would try port after port, then (or past 65535) wait forever."""
    import random

    from autotrack_studio.cli import PORT_ATTEMPTS

    count = PORT_ATTEMPTS if where == "a block of ports" else 4
    held: list = []
    for _ in range(50):
        first = random.randrange(20_000, 60_000) if count == PORT_ATTEMPTS else 65536 - count
        held = _occupy(first, count)
        if held or count != PORT_ATTEMPTS:
            break
    if not held:
        pytest.skip(f"ports {first}.. are in use on this machine")
    try:
        done = subprocess.run(
            [sys.executable, "-m", "autotrack.cli", "app", "demo", "--port", str(first)]
            + ["--sessions", str(workspace / "port_sessions")],
            cwd=workspace,
            capture_output=True,
            text=True,
            timeout=120,
        )
    finally:
        for listener in held:
            listener.close()
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "is taken" in done.stderr, done.stderr
    assert "Server stopped" not in done.stdout + done.stderr
