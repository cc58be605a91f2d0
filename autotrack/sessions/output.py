"""The file a session is recorded to, as the MCAP writer's output stream: it stays a readable
session whatever the disk does.

The writer's bytes are held in memory and reach the operating system only at `flush`, which
the recorder calls at record boundaries (the header, each closed chunk with its index, the
summary). When a write fails (a full disk, a quota, an I/O error), the file is cut back to the
end of the last complete flush and closed at once: nothing is written to it afterwards, even
when space comes back, so it holds every record flushed before the failure and reads as a
session cut short (`open_session`; `finished_copy` makes it a complete file). Writing more after
a failed write, as a plain buffered file would, appends records whose offsets no longer match
and leaves a file no reader can open.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import BinaryIO

try:
    import fcntl
except ImportError:  # not POSIX: no lock, a file being written reads as cut short
    fcntl = None  # type: ignore[assignment]


def _lock(handle: BinaryIO, kind: int) -> bool:
    """Take an advisory lock on the open file without waiting; False if another holds it."""
    if fcntl is None:
        return True
    try:
        fcntl.flock(handle.fileno(), kind | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    except OSError:
        return True  # a file system without locks (some network mounts): no marker
    return True


def recording_in_progress(handle: BinaryIO) -> bool:
    """Whether a recorder is writing the open session file: the recorder holds an exclusive
    advisory lock (flock) on it from creation to close, released by the operating system when
    the recorder's process ends however it ends, so a crashed recording never reads as one in
    progress. A reader's shared lock attempt fails while it is held (also from another open of
    the file in the same process)."""
    if fcntl is None or not _lock(handle, fcntl.LOCK_SH):
        return fcntl is not None
    fcntl.flock(handle.fileno(), fcntl.LOCK_UN)
    return False


class SessionFile:
    """A new file written at record boundaries only; closed for good by its first failed write.

    `error` is that failure (None while every write succeeded); `flushed_bytes` how much of the
    file is complete on disk.
    """

    def __init__(self, raw: BinaryIO, path: Path, *, fsync: bool = False) -> None:
        """raw: the new file, opened unbuffered for writing; fsync: sync it at each flush."""
        self.path = path
        self.error: OSError | None = None
        self.flushed_bytes = 0
        self._raw = raw
        self._fsync = fsync
        self._pending = bytearray()
        if fcntl is not None:
            _lock(raw, fcntl.LOCK_EX)  # "being recorded" (`recording_in_progress`)

    @property
    def closed(self) -> bool:
        return self._raw.closed

    def write(self, data: bytes) -> int:
        """Queue `data` for the next flush."""
        self._check_usable()
        self._pending += data
        return len(data)

    def tell(self) -> int:
        """The offset the next byte written will have."""
        return self.flushed_bytes + len(self._pending)

    def flush(self) -> None:
        """Hand everything queued to the OS (and to the disk, with fsync); on failure cut the
        file back to its last complete flush, close it and raise the OSError."""
        self._check_usable()
        try:
            self._write_pending()
            if self._fsync:
                os.fsync(self._raw.fileno())
        except OSError as error:
            self._abandon(error)
            raise
        self.flushed_bytes += len(self._pending)
        self._pending = bytearray()

    def close(self) -> None:
        """Close the file (what was not flushed is dropped). Safe to call twice."""
        self._pending = bytearray()
        self._raw.close()

    def _write_pending(self) -> None:
        with memoryview(self._pending) as pending:
            written = 0
            while written < len(pending):
                written += self._raw.write(pending[written:]) or 0

    def _check_usable(self) -> None:
        if self.error is not None:
            raise OSError(self.error.errno, f"no longer written after: {self.error}")
        if self._raw.closed:
            raise ValueError(f"{self.path} is closed")

    def _abandon(self, error: OSError) -> None:
        self.error = error
        self._pending = bytearray()
        try:
            self._raw.truncate(self.flushed_bytes)  # needs no free space
        except OSError:
            pass  # the cut-off record stays; readers stop before a record that runs past the end
        finally:
            self._raw.close()
