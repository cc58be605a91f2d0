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
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except AutoTrackError as error:
        print(f"autotrack: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("autotrack: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
