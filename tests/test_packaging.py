"""The package as pip installs it: every package listed, the core usable without the extras.

`.ci/wheel-smoke` builds and installs the real wheel; these tests keep the fast suite honest
about the same promises: pyproject.toml lists every package and data folder, and the library
and its commands run with viser and matplotlib absent (a core install), naming the extra to
install where one is needed.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import cv2
import numpy as np

from tests.sequences import moving_target_sequence

REPO = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())
SETUPTOOLS = PYPROJECT["tool"]["setuptools"]
TOP_LEVEL_SOURCES = ("autotrack", "app")
"""The folders holding the installed packages (the app's stays `app/` whatever it installs as)."""


def _source_dir(package: str) -> Path:
    """Where setuptools takes `package` from: its package-dir mapping, else its own path (a
    mapped parent package moves its children along)."""
    mapping = SETUPTOOLS.get("package-dir", {})
    parts = package.split(".")
    for cut in range(len(parts), 0, -1):
        prefix = ".".join(parts[:cut])
        if prefix in mapping:
            return REPO / mapping[prefix] / Path(*parts[cut:])
    return REPO / Path(*parts)


def test_every_package_of_the_source_tree_is_in_the_wheel_list() -> None:
    listed = {_source_dir(package).resolve() for package in SETUPTOOLS["packages"]}
    in_tree = {
        init.parent.resolve()
        for top in TOP_LEVEL_SOURCES
        for init in (REPO / top).rglob("__init__.py")
        if "__pycache__" not in init.parts
    }
    missing = sorted(str(path.relative_to(REPO)) for path in in_tree - listed)
    assert not missing, f"add these packages to [tool.setuptools] packages: {missing}"
    absent = sorted(str(path) for path in listed if not path.is_dir())
    assert not absent, f"listed packages without a folder: {absent}"


def _data_files(folder: Path) -> list[Path]:
    """The files of the package in `folder` that are not Python (those of its subpackages,
    folders with an __init__.py, are theirs)."""
    files = []
    for path in folder.rglob("*"):
        if not path.is_file() or path.suffix in (".py", ".pyc") or "__pycache__" in path.parts:
            continue
        between = path.relative_to(folder).parents
        if not any((folder / part / "__init__.py").exists() for part in between if part.parts):
            files.append(path)
    return files


def test_the_package_data_globs_cover_every_data_file_of_the_packages() -> None:
    data = SETUPTOOLS["package-data"]
    for package in SETUPTOOLS["packages"]:
        folder = _source_dir(package)
        covered = {match for pattern in data.get(package, []) for match in folder.glob(pattern)}
        loose = sorted(str(p.relative_to(REPO)) for p in _data_files(folder) if p not in covered)
        assert not loose, f"not in the wheel (package-data of {package}): {loose}"


def test_the_licence_files_the_metadata_names_exist() -> None:
    project = PYPROJECT["project"]
    assert project["license"] == "MIT"
    assert "MIT License" in (REPO / "LICENSE").read_text()
    for pattern in project["license-files"]:
        matches = list(REPO.glob(pattern))
        # The NanoTrack licence travels with its models (autotrack/nanotrack/, issue 20).
        assert matches or not (REPO / pattern).parent.parent.is_dir(), pattern


def _core_only(code: str, cwd: Path) -> subprocess.CompletedProcess:
    """Run `code` in a fresh interpreter where viser and matplotlib cannot be imported."""
    blocked = "import sys\nfor _name in ('viser', 'matplotlib'):\n    sys.modules[_name] = None\n"
    return subprocess.run(
        [sys.executable, "-c", blocked + code],
        cwd=cwd,
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )


def test_a_core_install_tracks_and_names_the_extra_of_the_app_and_the_plots(tmp_path) -> None:
    generated = moving_target_sequence(num_frames=8)
    sequence = tmp_path / "mover"
    (sequence / "img").mkdir(parents=True)
    for index, frame in enumerate(generated.frames):
        cv2.imwrite(str(sequence / "img" / f"{index + 1:04d}.png"), frame[:, :, ::-1])
    one_based = generated.boxes + np.array([1, 1, 0, 0])
    np.savetxt(sequence / "groundtruth_rect.txt", one_based, fmt="%.3f", delimiter=",")
    code = (
        "from autotrack.cli import main\n"
        "import autotrack\n"
        f"code = main(['track', {str(sequence)!r}, '--quiet'])\n"
        "assert 'viser' not in [m.split('.')[0] for m in sys.modules if sys.modules[m]]\n"
        "sys.exit(code)\n"
    )
    tracked = _core_only(code, tmp_path)
    assert tracked.returncode == 0, tracked.stderr
    assert "frames: 8 · start-up" in tracked.stdout
    app = _core_only("from autotrack.cli import main\nsys.exit(main(['app']))\n", tmp_path)
    assert app.returncode == 2 and "Traceback" not in app.stderr
    assert app.stderr.strip() == (
        "autotrack: error: autotrack app needs viser, which is not installed: "
        "pip install 'autotrack-studio[app]'"
    )
    plots = _core_only(
        f"from autotrack.cli import main\nsys.exit(main(['bench', {str(tmp_path)!r}, '--plots']))\n",
        tmp_path,
    )
    assert plots.returncode == 2
    assert "--plots needs matplotlib" in plots.stderr and "[plots]'" in plots.stderr
