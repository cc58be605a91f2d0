"""The optional parts of the package (pyproject.toml's extras) and the message when one is missing.

The core install (`pip install autotrack-studio`) tracks, localises, benchmarks and records
sessions; `[app]` adds the browser app (viser), `[plots]` the PNG plots (matplotlib) and
`[cluster]` Dask. Code that needs an extra calls `require_extra` before any work starts, so a
missing one ends the command in one line naming what to install.
"""

from __future__ import annotations

from importlib.util import find_spec

from autotrack.errors import MissingExtraError

DISTRIBUTION = "autotrack-studio"
"""The name pip installs the package under."""


def install_hint(extra: str) -> str:
    """The command that installs `extra`."""
    return f"pip install '{DISTRIBUTION}[{extra}]'"


def has_module(module: str) -> bool:
    """Whether top-level `module` can be imported (without importing it)."""
    return find_spec(module) is not None


def require_extra(module: str, extra: str, purpose: str) -> None:
    """MissingExtraError naming `extra` when `module` is not installed; `purpose` says what
    needs it ("autotrack app", "--plots")."""
    if not has_module(module):
        raise MissingExtraError(
            f"{purpose} needs {module}, which is not installed: {install_hint(extra)}"
        )
