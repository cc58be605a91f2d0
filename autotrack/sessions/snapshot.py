"""A finished copy of a session file that may still be being recorded (or was cut short).

A session file gets its summary and footer only when the recording closes; until then readers
see it as cut short. `finished_copy` copies every complete record written so far into a new,
finished MCAP, so a download taken mid-session is a valid file of its own.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.writer import CompressionType, Writer

from autotrack.errors import SessionError
from autotrack.sessions.records import iter_records, scan_records


def finished_copy(path: str | Path) -> bytes:
    """The session file's bytes as a complete MCAP: the file itself when it is finished, else
    its complete records copied into a finished file (summary and footer written)."""
    path = Path(path)
    try:
        handle = open(path, "rb")  # noqa: SIM115 - closed below
    except OSError as error:
        raise SessionError(f"cannot open session file {path}: {error}") from error
    with handle:
        size = os.fstat(handle.fileno()).st_size
        limit, complete = scan_records(handle, size, str(path))
        if complete:
            handle.seek(0)
            return handle.read(size)
        out = io.BytesIO()
        writer = Writer(
            out, compression=CompressionType.ZSTD, enable_crcs=True, enable_data_crcs=True
        )
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for record in iter_records(handle, limit):
            if isinstance(record, Header):
                writer.start(profile=record.profile, library=record.library)
            elif isinstance(record, Schema):
                schemas[record.id] = writer.register_schema(
                    record.name, record.encoding, record.data
                )
            elif isinstance(record, Channel):
                channels[record.id] = writer.register_channel(
                    record.topic,
                    record.message_encoding,
                    schemas.get(record.schema_id, 0),
                    record.metadata,
                )
            elif isinstance(record, Message):
                writer.add_message(
                    channels[record.channel_id],
                    record.log_time,
                    record.data,
                    record.publish_time,
                    record.sequence,
                )
            elif isinstance(record, Attachment):
                writer.add_attachment(
                    record.create_time, record.log_time, record.name, record.media_type, record.data
                )
            elif isinstance(record, Metadata):
                writer.add_metadata(record.name, record.metadata)
        writer.finish()
        return out.getvalue()
