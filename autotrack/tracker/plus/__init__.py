"""autotrack+: the changes beyond the authors' release (docs/tracker.md, "Beyond the release"):
robust variation and acting ASR (`robust`), re-detection (`redetect`), the long-term memory
(`memory`), rotation (`rotation`), the aspect filter (`aspect`) and the motion prior (`motion`).
The faithful `AutoTrack` never imports them; `AutoTrackPlus` (`plus.tracker`) adds them."""
