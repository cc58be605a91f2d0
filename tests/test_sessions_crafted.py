"""Crafted session files end in one SessionError line, never a traceback or a huge allocation
(issue 17)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from autotrack.cli import main
from autotrack.errors import SessionError
from autotrack.sessions import open_session
from autotrack.sessions.encoding import SESSION_METADATA_NAME
from tests.test_sessions import _record


@pytest.fixture(scope="module")
def genuine(tmp_path_factory) -> Path:
    return _record(tmp_path_factory.mktemp("genuine")).path


def _rewrite(
    source: Path,
    target: Path,
    metadata: Callable[[dict], None] = lambda _: None,
    row: Callable[[dict], None] = lambda _: None,
    topic: Callable[[str], str] = lambda name: name,
) -> Path:
    """`source` written again with its session metadata, its signal rows and its topic names
    changed in place by the given functions."""
    with open(source, "rb") as handle, open(target, "wb") as out:
        reader = make_reader(handle)
        writer = Writer(out, compression=CompressionType.ZSTD)
        writer.start(profile="", library="crafted")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data
                )
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    topic(channel.topic),
                    channel.message_encoding,
                    schemas.get(channel.schema_id, 0),
                    dict(channel.metadata),
                )
            data = message.data
            if channel.topic.endswith("/signals"):
                payload = json.loads(data)
                row(payload)
                data = json.dumps(payload).encode()
            writer.add_message(
                channels[channel.id], message.log_time, data, message.publish_time, message.sequence
            )
        for record in reader.iter_metadata():
            values = dict(record.metadata)
            if record.name == SESSION_METADATA_NAME:
                metadata(values)
            writer.add_metadata(record.name, values)
        writer.finish()
    return target


def _set(key, value):
    return lambda mapping: mapping.__setitem__(key, value)


CRAFTED = {
    "text fps": ({"metadata": _set("fps", "fast")}, "not a positive number|could not convert"),
    "nan fps": ({"metadata": _set("fps", "nan")}, "not a positive number"),
    "tracker_params not JSON": ({"metadata": _set("tracker_params", "[1, 2")}, "JSONDecodeError"),
    "tracker_params a list": ({"metadata": _set("tracker_params", "[1]")}, "not a JSON object"),
    "missing frame_index": ({"row": lambda row: row.pop("frame_index")}, "KeyError"),
    "frame_index 1e10": ({"row": _set("frame_index", 1e10)}, "out of range"),
    "frame_index -1": ({"row": _set("frame_index", -1)}, "out of range"),
    "frame_index text": ({"row": _set("frame_index", "3")}, "not a whole number"),
    "NUL in a target id": ({"topic": lambda name: name.replace("/t1/", "/t\x001/")}, "control"),
    "newline in a target id": (
        {"topic": lambda name: name.replace("/t1/", "/t1\nT9,0,0/")},
        "control",
    ),
}


@pytest.mark.parametrize(("change", "message"), CRAFTED.values(), ids=CRAFTED.keys())
def test_a_crafted_session_is_refused_in_one_line(
    genuine: Path, tmp_path: Path, change: dict, message: str, capsys
) -> None:
    crafted = _rewrite(genuine, tmp_path / "crafted.mcap", **change)
    with pytest.raises(SessionError, match=message):
        open_session(crafted)
    for argv in (
        ["session", "info", str(crafted)],
        ["session", "export", str(crafted), "--csv", str(tmp_path / "t.csv")],
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("autotrack: error: "), err
    assert not (tmp_path / "t.csv").exists()


def test_the_rewrite_alone_keeps_a_readable_session(genuine: Path, tmp_path: Path) -> None:
    session = open_session(_rewrite(genuine, tmp_path / "same.mcap"))
    assert session.targets == open_session(genuine).targets
