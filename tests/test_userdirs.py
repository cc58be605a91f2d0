"""The tool's per-user folders: one cache root, one data folder, never the current folder."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from autotrack import userdirs


@pytest.fixture
def home(monkeypatch, tmp_path) -> Path:
    """A fresh home folder with none of the variables set."""
    for name in (userdirs.CACHE_ENV, "XDG_CACHE_HOME", "XDG_DATA_HOME"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.chdir(tmp_path)
    return tmp_path / "home"


def test_defaults_are_the_xdg_folders_under_home(home: Path) -> None:
    assert userdirs.cache_root() == home / ".cache" / "autotrack"
    assert userdirs.data_root() == home / ".local" / "share" / "autotrack"
    assert userdirs.default_sessions_dir() == home / ".local/share/autotrack/sessions"


def test_xdg_variables_move_both_folders_and_the_tool_variable_wins_for_the_cache(
    home: Path, monkeypatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg-cache"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg-data"))
    assert userdirs.cache_root() == tmp_path / "xdg-cache" / "autotrack"
    assert userdirs.default_sessions_dir() == tmp_path / "xdg-data" / "autotrack" / "sessions"
    monkeypatch.setenv(userdirs.CACHE_ENV, str(tmp_path / "mine"))
    assert userdirs.cache_root() == tmp_path / "mine"


def test_relative_xdg_values_are_ignored_so_nothing_lands_in_the_current_folder(
    home: Path, monkeypatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", "cache")
    monkeypatch.setenv("XDG_DATA_HOME", "data")
    assert userdirs.cache_root() == home / ".cache" / "autotrack"
    assert userdirs.data_root() == home / ".local" / "share" / "autotrack"
    assert sorted(os.listdir(tmp_path)) == ["home"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_an_unwritable_cache_falls_back_to_a_temporary_folder(home: Path, monkeypatch, tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    monkeypatch.setenv(userdirs.CACHE_ENV, str(locked / "cache"))
    root = userdirs.cache_root()
    assert root.name == f"autotrack-cache-{os.getuid()}" and userdirs.is_writable_dir(root)


def test_a_cache_path_that_is_a_file_falls_back_to_a_temporary_folder(
    home: Path, monkeypatch, tmp_path: Path
) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    monkeypatch.setenv(userdirs.CACHE_ENV, str(blocker))
    root = userdirs.cache_root()
    assert root.name == f"autotrack-cache-{os.getuid()}" and userdirs.is_writable_dir(root)
