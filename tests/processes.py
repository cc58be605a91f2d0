"""Running a short script in a fresh Python process (what is imported at start-up, first loads)."""

from __future__ import annotations

import subprocess
import sys


def printed_by_fresh_python(script: str) -> list[str]:
    """The words `script` prints, run by a new interpreter; fails the test with the script's
    stderr when it fails."""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return done.stdout.split()
