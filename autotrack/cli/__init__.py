"""The `autotrack` command line: one sub-command module per task."""

from __future__ import annotations

import argparse
import importlib
import sys

from autotrack.errors import AutoTrackError

# Each module defines `add_parser(subparsers)`; the parser it adds sets `func`.
_COMMAND_MODULES = ("track", "bench", "sweep", "localize", "session", "app")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="autotrack",
        description="AutoTrack correlation-filter tracking for UAV footage.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True)
    for name in _COMMAND_MODULES:
        try:
            module = importlib.import_module(f"autotrack.cli.{name}")
        except ModuleNotFoundError as error:
            if error.name == f"autotrack.cli.{name}":
                continue
            raise
        module.add_parser(subparsers)
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
