"""The `autotrack` command line: one sub-command module per task."""

from __future__ import annotations

import argparse
import importlib
import sys
from importlib.metadata import entry_points

from autotrack.errors import AutoTrackError

# Each module defines `add_parser(subparsers)`; the parser it adds sets `func`.
_COMMAND_MODULES = ("track", "bench", "sweep", "localize", "synth", "session")
COMMANDS_ENTRY_POINT_GROUP = "autotrack.commands"
"""Other packages add sub-commands here: an entry point naming their `add_parser` (the web app
adds `autotrack app` this way, so the library never imports it)."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="autotrack",
        description="AutoTrack correlation-filter tracking for UAV footage.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True)
    for name in _COMMAND_MODULES:
        importlib.import_module(f"autotrack.cli.{name}").add_parser(subparsers)
    for entry_point in entry_points(group=COMMANDS_ENTRY_POINT_GROUP):
        entry_point.load()(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    _show_any_path()
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except AutoTrackError as error:
        print(f"autotrack: error: {_one_line(str(error))}", file=sys.stderr)
        return 2
    except OSError as error:  # a file that cannot be read or written, a full disk
        where = f"{error.filename}: " if error.filename else ""
        print(f"autotrack: error: {where}{error.strerror or error}", file=sys.stderr)
        return 2
    except UnicodeDecodeError as error:
        print(
            f"autotrack: error: an input file is not UTF-8 text ({error.reason})", file=sys.stderr
        )
        return 2
    except RecursionError:
        print("autotrack: error: an input file is nested too deeply", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("autotrack: interrupted", file=sys.stderr)
        return 130


def _show_any_path() -> None:
    """Print paths that are not valid UTF-8 (a Latin-1 folder name) with their odd bytes as
    `\\xe9` instead of failing on them (they reach the program surrogate-escaped)."""
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        if reconfigure is not None:
            reconfigure(errors="backslashreplace")


def _one_line(text: str) -> str:
    """`text` with its line breaks and NUL characters shown escaped."""
    return text.replace("\x00", "\\x00").replace("\r", "\\r").replace("\n", "\\n")


if __name__ == "__main__":
    sys.exit(main())
