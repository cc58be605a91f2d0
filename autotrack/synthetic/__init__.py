"""A synthetic test bed like the paper's localisation experiment (section 5.3, Table 3).

An indoor room (wooden floor, painted walls with posters and doors, tiled ceiling) with four
distinct planar landmarks, two on the back wall and two on stands at different depths, filmed by
a camera modelled on the paper's Intel RealSense R200 colour stream (1280x720, 10 fps, ~70 deg
horizontal field of view, mild lens distortion) moving along one of six trajectories; the ground
truth (camera poses, intrinsics, landmark positions, per-frame landmark boxes) is exact.

`world` (the room, its landmarks and planes), `textures` (procedural, seeded), `trajectories`
(what a sequence is and what changes along it), `renderer` (frames and ground-truth files),
`testbed` (the written test bed and the app's embedded demo); `aerial` (top-down drone scenes
of the tracker's failure patterns: look-alike cars, a walker in a group, a tiny car).

World frame: x right, y forward (towards the back wall), z up, metres. Camera: OpenCV convention.
"""
