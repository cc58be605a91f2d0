"""The hybrid tracker: AutoTrack+ and NanoTrack on the same frames, fused frame by frame by each
tracker's own evidence (`tracker`: the rule, its parameters and the result saying whom it
trusted)."""

from autotrack.hybrid.tracker import HybridParams, HybridResult, HybridTracker, fuse

__all__ = ["HybridParams", "HybridResult", "HybridTracker", "fuse"]
