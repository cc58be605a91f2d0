"""The synthetic localisation test bed: the room and its landmarks (`world`), procedural
textures (`textures`), camera trajectories (`trajectories`), the renderer (`renderer`) and the
written sequences and embedded demo (`testbed`)."""
