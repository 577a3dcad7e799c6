"""Read messages from one MCAP drive: a file, or a folder of files (a split ROS 2 bag).

Every failure to parse the bytes (not MCAP, truncated, bad chunk CRC, undecodable message)
becomes one DrivewmError naming the file. Messages are decoded lazily and only for the channels
the caller selects, so logs with exotic schemas on other topics still load.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from mcap import exceptions
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory

from drivewm.errors import DrivewmError


@dataclasses.dataclass(frozen=True)
class ChannelInfo:
    """One MCAP channel: ``encoding`` is the message encoding (protobuf, json, cdr, ...)."""

    topic: str
    schema_name: str
    encoding: str


@dataclasses.dataclass
class Message:
    """A decoded message: ``log_time_ns`` from the MCAP record; ``data`` a protobuf message,
    a ROS 2 dynamic message or a JSON dict, as the channel's encoding gives."""

    channel: ChannelInfo
    log_time_ns: int
    data: Any


def log_files(path: str | Path) -> list[Path]:
    """The MCAP files of one drive: ``path`` itself, or the ``*.mcap`` files of a folder
    (a split bag: ``name_0.mcap``, ``name_1.mcap``, ... in numeric order)."""
    path = Path(path)
    if path.is_dir():
        files = sorted(path.glob("*.mcap"), key=_split_index)
        if not files:
            raise DrivewmError(f"{path}: folder holds no .mcap files")
        return files
    if not path.is_file():
        raise DrivewmError(f"{path}: no such file")
    return [path]


def _split_index(p: Path) -> tuple[int, str]:
    tail = p.stem.rsplit("_", 1)[-1]
    return (int(tail) if tail.isdigit() else -1, p.name)


def read_metadata(path: Path) -> dict[str, dict[str, str]]:
    """The MCAP metadata records of one file, by name."""
    with _guard(path), open(path, "rb") as f:
        return {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}


def list_channels(path: Path) -> list[ChannelInfo]:
    """Channels listed in the file's summary (also the ones without messages); empty if the
    file has no summary section."""
    with _guard(path), open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    if summary is None:
        return []
    return [_channel_info(summary.schemas.get(c.schema_id), c) for c in summary.channels.values()]


def iter_messages(path: Path, wanted: Callable[[ChannelInfo], bool]) -> Iterator[Message]:
    """Decoded messages of the channels ``wanted`` selects, in log-time order, with chunk CRCs checked."""
    decoders: dict[int, Callable[[bytes], Any] | None] = {}
    with _guard(path), open(path, "rb") as f:
        for schema, channel, record in make_reader(f, validate_crcs=True).iter_messages(log_time_order=True):
            if channel.id not in decoders:
                info = _channel_info(schema, channel)
                decoders[channel.id] = _decoder(info, schema) if wanted(info) else None
            decode = decoders[channel.id]
            if decode is not None:
                yield Message(_channel_info(schema, channel), record.log_time, decode(record.data))


def _channel_info(schema, channel) -> ChannelInfo:
    return ChannelInfo(channel.topic, schema.name if schema else "", channel.message_encoding)


def _decoder(info: ChannelInfo, schema) -> Callable[[bytes], Any]:
    """A bytes -> message function for the channel's encoding."""
    if info.encoding == "json":
        return json.loads
    if info.encoding == "protobuf":
        decode = ProtobufDecoderFactory().decoder_for(info.encoding, schema)
    elif info.encoding == "cdr":
        decode = Ros2DecoderFactory().decoder_for(info.encoding, schema)
    else:
        decode = None
    if decode is None:
        raise DrivewmError(f"topic {info.topic}: cannot decode message encoding {info.encoding!r} ({info.schema_name})")
    return decode


class _guard:
    """Turn any failure to parse the file into a DrivewmError naming it."""

    def __init__(self, path: Path):
        self.path = path

    def __enter__(self) -> None:
        return None

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None or issubclass(exc_type, GeneratorExit):
            return False
        if issubclass(exc_type, DrivewmError):
            raise DrivewmError(f"{self.path}: {exc}") from None
        if issubclass(exc_type, OSError):
            raise DrivewmError(f"{self.path}: cannot read ({exc})") from None
        if issubclass(exc_type, Exception):
            raise DrivewmError(f"{self.path}: {_describe(exc)}") from None
        return False


def _describe(exc: BaseException) -> str:
    """One line saying what is wrong with the bytes."""
    name = type(exc).__name__
    if isinstance(exc, exceptions.InvalidMagic):
        return "not an MCAP file (bad magic bytes)"
    if isinstance(exc, (exceptions.EndOfFile, exceptions.RecordLengthLimitExceeded, EOFError)):
        return f"truncated or corrupt MCAP ({name})"
    if "CRC" in name:
        return f"corrupt MCAP: {exc}"
    return f"corrupt MCAP or undecodable message ({name}: {exc})"
