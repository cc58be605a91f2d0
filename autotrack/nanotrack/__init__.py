"""NanoTrack V2, OpenCV's Siamese tracker for embedded CPUs, with AutoTrack's call shape:
`NanoTrack().init(frame_rgb, box)` / `.update(frame_rgb)` return `TrackResult`s whose response
map is the network's score map (`tracker`). The ONNX models and their licence are in `models/`."""

from autotrack.nanotrack.tracker import NanoTrack, NanoTrackParams

__all__ = ["NanoTrack", "NanoTrackParams"]
