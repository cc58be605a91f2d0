"""One pipeline for frames -> targets -> camera pose -> session recording (`Pipeline`), used by
the command line, the app and the benchmark scripts; `localize_sequence` runs it over a whole
sequence, `live.run_live` over live input."""

from autotrack.pipeline.localize import localize_sequence
from autotrack.pipeline.pipeline import Pipeline
from autotrack.pipeline.recording import Recording
from autotrack.pipeline.targets import FrameOutcome, TrackedTarget

__all__ = ["FrameOutcome", "Pipeline", "Recording", "TrackedTarget", "localize_sequence"]
