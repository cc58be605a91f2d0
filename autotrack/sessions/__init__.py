"""Sessions in MCAP: every tracked frame, pose and user edit, recorded crash-safely and read back.

`schemas` (the channels: published JSON schemas, encodings, topics), `messages` (what each
message holds), `recorder` (writing), `reader` (reading, also a file cut short), `session` (what
is read back) and `exports` (OTB tracks, CSV, TUM poses, MOT Challenge, CVAT for video 1.1 and
the evo command).
"""

from autotrack.sessions.exports import write_otb_tracks, write_tracks_csv, write_tum_poses
from autotrack.sessions.reader import open_session
from autotrack.sessions.recorder import SessionRecorder, SessionWriteError
from autotrack.sessions.session import PoseTrack, RecordedTarget, Session, SessionEvent

__all__ = [
    "PoseTrack",
    "RecordedTarget",
    "Session",
    "SessionEvent",
    "SessionRecorder",
    "SessionWriteError",
    "open_session",
    "write_otb_tracks",
    "write_tracks_csv",
    "write_tum_poses",
]
