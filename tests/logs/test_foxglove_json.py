"""JSON-encoded Foxglove logs read back as the same DriveLog as drivewm's protobuf logs."""

from __future__ import annotations

import json

from json_writer import write_log_json
from mcap.reader import make_reader

from drivewm.logs.reader import read_log


def test_json_log_reads_as_same_drive(tmp_path, synthetic_log, synthetic_mcap, assert_same_log):
    path = write_log_json(synthetic_log, tmp_path / "json.mcap")
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert {c.message_encoding for c in summary.channels.values()} == {"json"}
    assert {s.encoding for s in summary.schemas.values()} == {"jsonschema"}
    from_json = read_log(path)
    assert_same_log(from_json, synthetic_log)
    assert_same_log(from_json, read_log(synthetic_mcap), rot_atol=0.0)  # same wire values, same numbers


def test_json_log_is_strict_json(tmp_path, synthetic_log):
    """The NaN pose gap is written as null (strict JSON), and still comes back as a gap."""
    path = write_log_json(synthetic_log, tmp_path / "json.mcap")
    with open(path, "rb") as f:
        payloads = [m.data for _, c, m in make_reader(f).iter_messages() if c.topic == "/tf"]
    for data in payloads:
        json.loads(data, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
    assert b"null" in payloads[3]


def test_unindexed_log_without_summary_reads_the_same(tmp_path, synthetic_log, assert_same_log):
    path = write_log_json(synthetic_log, tmp_path / "bare.mcap", indexed=False)
    with open(path, "rb") as f:
        assert make_reader(f).get_summary() is None
    assert_same_log(read_log(path), synthetic_log)
