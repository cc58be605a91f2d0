"""The hybrid tracker: AutoTrack+ and NanoTrack on the same frames, fused frame by frame by each
tracker's own evidence (`tracker`: the rule, its parameters and the result saying whom it
trusted); `factory.make_tracker` makes any tracker by name."""

from importlib import import_module

# Loaded on first use: `autotrack.hybrid.factory` (imported by the benchmark's peers) stays light.
_LAZY = {name: "autotrack.hybrid.tracker" for name in ("HybridParams", "HybridResult")}
_LAZY.update({name: "autotrack.hybrid.tracker" for name in ("HybridTracker", "fuse")})


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'autotrack.hybrid' has no attribute {name!r}")
    return getattr(import_module(module), name)


__all__ = ["HybridParams", "HybridResult", "HybridTracker", "fuse"]
