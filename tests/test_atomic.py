"""Issue 15 item 4: atomic, durable writes; JSON-lines appends that survive a torn last row; folders
replaced without a moment of absence; model folders whose weights and config never mix."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time

import pytest
import torch

from drivewm.atomic import JsonlAppender, atomic_path, read_jsonl, remove_dead_temporaries, write_bytes
from drivewm.cli import main
from drivewm.errors import DrivewmError
from drivewm.train import checkpoint
from drivewm.train.checkpoint import load_model_folder, save_model_folder


def test_a_torn_last_row_is_dropped_and_cut_before_the_next_append(tmp_path):
    path = tmp_path / "metrics.jsonl"
    path.write_text('{"step": 1}\n{"step": 2}\n{"step": 3, "lo')  # killed in the middle of row 3
    assert read_jsonl(path) == [{"step": 1}, {"step": 2}]
    with JsonlAppender(path, keep=lambda r: r["step"] <= 1) as log:  # a run resuming from step 1
        log.write({"step": 2, "loss": 0.5})
    assert path.read_text() == '{"step": 1}\n{"step": 2, "loss": 0.5}\n'
    path.write_bytes(path.read_bytes() + b"\x00\x00\x00\n")  # a crash can also leave zeros
    assert read_jsonl(path) == [{"step": 1}, {"step": 2, "loss": 0.5}]


def test_a_bad_row_before_the_end_is_an_error_naming_the_line(tmp_path):
    path = tmp_path / "m.jsonl"
    path.write_text('{"step": 1}\nnot json\n{"step": 3}\n')
    with pytest.raises(DrivewmError, match=r"m\.jsonl: line 2 is not JSON"):
        read_jsonl(path)


def test_writes_are_fsynced(tmp_path, monkeypatch):
    synced = []
    real = os.fsync
    monkeypatch.setattr(os, "fsync", lambda fd: (synced.append(os.readlink(f"/proc/self/fd/{fd}")), real(fd)))
    write_bytes(tmp_path / "a.bin", b"data")
    assert len(synced) == 2 and synced[0].endswith("/a.bin")  # the data, under its temporary name
    assert synced[1] == str(tmp_path)  # then the folder entry of the rename


def test_replacing_a_folder_never_leaves_a_moment_without_it(tmp_path):
    target = tmp_path / "model"
    with atomic_path(target) as tmp:
        tmp.mkdir()
        (tmp / "value").write_text("0")
    misses, done = [], threading.Event()

    def reader():
        while not done.is_set():
            try:
                (target / "value").read_text()
            except FileNotFoundError:
                misses.append(1)

    thread = threading.Thread(target=reader)
    thread.start()
    try:
        for i in range(1, 80):
            with atomic_path(target) as tmp:
                tmp.mkdir()
                (tmp / "value").write_text(str(i))
    finally:
        done.set()
        thread.join()
    assert (target / "value").read_text() == "79" and not misses, f"{len(misses)} reads found no folder"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model"]  # no temporaries left


def _save(path, i: int) -> None:
    save_model_folder(path, "toy", {"i": i}, {"w": torch.full((64,), float(i))})


def test_a_save_interrupted_between_its_two_renames_is_never_read_as_a_mix(tmp_path, monkeypatch):
    _save(tmp_path, 1)
    monkeypatch.setattr(checkpoint, "READ_ATTEMPTS", 2)
    with monkeypatch.context() as m:
        m.setattr(checkpoint, "write_json", lambda *a: (_ for _ in ()).throw(KeyboardInterrupt()))  # killed here
        with pytest.raises(KeyboardInterrupt):
            _save(tmp_path, 2)
    with pytest.raises(DrivewmError, match="come from different saves"):
        load_model_folder(tmp_path, "toy")
    _save(tmp_path, 2)
    info, state = load_model_folder(tmp_path, "toy")
    assert info["config"] == {"i": 2} and torch.equal(state["w"], torch.full((64,), 2.0))


def test_concurrent_reader_sees_matching_weights_and_config(tmp_path):
    _save(tmp_path, 0)
    seen, done = [], threading.Event()

    def writer():  # at least 39 saves, and on until the reader has loaded 20 times (a busy machine's
        i = 1  # scheduler can let the saves finish before the reader's fifth load: a flaky count, not a bug)
        while i < 40 or len(seen) < 20:
            _save(tmp_path, i)
            i += 1
        done.set()

    thread = threading.Thread(target=writer)
    thread.start()
    while not done.is_set():
        info, state = load_model_folder(tmp_path, "toy")
        seen.append((info["config"]["i"], float(state["w"][0])))
    thread.join()
    assert len(seen) > 5 and all(i == w for i, w in seen), [s for s in seen if s[0] != s[1]][:5]


def test_equal_saves_give_equal_bytes(tmp_path):
    _save(tmp_path / "a", 3)
    _save(tmp_path / "b", 3)
    for name in ("model.safetensors", "config.json"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    assert len(json.loads((tmp_path / "a" / "config.json").read_text())["revision"]) == 32


def test_saved_weights_are_readable_by_others_as_any_file_is(tmp_path):
    """safetensors writes its file 0600; a model folder (a run's, or the shipped weights a wheel is
    built from) must be as readable as the config beside it, under the umask, and executables keep theirs."""
    _save(tmp_path / "m", 3)
    umask = os.umask(0)
    os.umask(umask)
    for name in ("model.safetensors", "config.json"):
        assert os.stat(tmp_path / "m" / name).st_mode & 0o777 == 0o666 & ~umask, name
    with atomic_path(tmp_path / "tool") as tmp:
        tmp.write_text("#!/bin/sh\n")
        tmp.chmod(0o755)
    assert os.stat(tmp_path / "tool").st_mode & 0o777 == 0o755


_WRITER = """
import sys, time
from drivewm.atomic import atomic_path
with atomic_path(sys.argv[1]) as tmp:
    tmp.write_bytes(b"half a file")
    print("writing", flush=True)
    time.sleep(120)
"""


def _writer(target) -> subprocess.Popen:
    """A process stopped in the middle of an atomic write of ``target``."""
    proc = subprocess.Popen([sys.executable, "-c", _WRITER, str(target)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline() == "writing\n"
    return proc


def test_only_temporaries_of_writers_killed_outright_are_removed(tmp_path):
    killed, live = _writer(tmp_path / "a.bin"), _writer(tmp_path / "b.bin")
    try:
        killed.kill()  # SIGKILL: no finally runs, the temporary stays behind
        killed.wait()
        host, ns = next(tmp_path.glob(".a.bin.*.tmp")).name.split(".")[3].rsplit("-", 2)[:2]
        elsewhere = tmp_path / ".c.bin.node-7-4026531836-12345.k2j4x8y1.tmp"  # another host's writer
        older = tmp_path / ".d.bin.k2j4x8y1.tmp"  # a name without its maker (drivewm before this change)
        # a container sharing this host name: the killed writer's pid means nothing in its PID namespace
        container = tmp_path / f".e.bin.{host}-{int(ns) + 1}-{killed.pid}.k2j4x8y1.tmp"
        for folder in (elsewhere, older, container):
            folder.mkdir()
        left = sorted(p.name for p in tmp_path.glob(".*.tmp"))
        assert len(left) == 5 and [n.split(".")[1] for n in left] == ["a", "b", "c", "d", "e"]
        gone = remove_dead_temporaries(tmp_path)
        assert [p.name for p in gone] == [left[0]]  # the killed writer's
        assert sorted(p.name for p in tmp_path.glob(".*.tmp")) == left[1:]
    finally:
        live.kill()
        live.wait()
    assert [p.name for p in remove_dead_temporaries(tmp_path)] == [left[1]]
    assert not (tmp_path / "a.bin").exists() and not (tmp_path / "b.bin").exists()


@pytest.mark.slow
def test_simulate_killed_mid_drive_then_rerun_leaves_no_temporaries_and_the_same_log(tmp_path):
    """``drivewm simulate`` killed with SIGKILL while writing a drive, run again: the rerun removes the dead
    run's hidden half-written log and writes the drive, byte for byte as an uninterrupted run does."""
    argv = ["simulate", "--duration", "4", "--width", "160", "--height", "96", "--seed", "3"]
    cmd = [sys.executable, "-m", "drivewm.cli", *argv, "--out", str(tmp_path / "killed")]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while proc.poll() is None and time.time() < deadline:  # until some ticks are written
        if sum(f.stat().st_size for f in (tmp_path / "killed").glob(".*.tmp/*.mcap")) > 100_000:
            break
        time.sleep(0.005)
    proc.kill()
    proc.wait()
    assert list((tmp_path / "killed").glob(".*.tmp")) and not list((tmp_path / "killed").glob("*.mcap"))
    assert subprocess.run(cmd, capture_output=True, timeout=300).returncode == 0
    assert not list((tmp_path / "killed").glob(".*.tmp"))
    assert main([*argv, "--out", str(tmp_path / "whole")]) == 0
    (log,) = (tmp_path / "killed").glob("*.mcap")
    assert log.read_bytes() == (tmp_path / "whole" / log.name).read_bytes()


def _dead_pid() -> int:
    """The pid of a process that ran and ended (reaped): no process of this host has it now."""
    proc = subprocess.Popen(["true"])
    proc.wait()
    return proc.pid


def test_a_writers_first_write_into_a_folder_removes_the_dead_temporaries_there(tmp_path):
    """Every writer (issue 70), not only those that call remove_dead_temporaries: the first atomic write of a
    process into a folder sweeps it, so a killed run's torn file does not outlive the rerun; a live writer's
    temporary stays."""
    from drivewm.atomic import _HOST, _PIDNS

    dead = tmp_path / "gen" / f".generated-000000.tar.{_HOST}-{_PIDNS}-{_dead_pid()}.k2j4x8y1.tmp"
    live = tmp_path / "gen" / f".sample_001.mp4.{_HOST}-{_PIDNS}-{os.getpid()}.q8w2e4r6.tmp"
    for folder in (dead, live):
        folder.mkdir(parents=True)
        (folder / folder.name.split(".")[1]).write_bytes(b"torn")
    write_bytes(tmp_path / "gen" / "sample_000.mp4", b"whole")
    assert sorted(p.name for p in (tmp_path / "gen").iterdir()) == sorted([live.name, "sample_000.mp4"])


def test_metrics_rows_are_strict_json(tmp_path):
    """A non-finite number is written as null (the metrics files' documented form), never a bare NaN, which
    no strict JSON reader takes; numpy scalars are written as numbers."""
    import math

    import numpy as np

    from drivewm.atomic import write_json

    with JsonlAppender(tmp_path / "metrics.jsonl") as log:
        log.write({"step": 1, "loss": float("nan"), "grad_norm": np.float32(2.5), "lr": [math.inf, -math.inf]})
    write_json(tmp_path / "metrics.json", {"tse": np.float64("nan"), "clips": {"a": {"cse": 1.0}}})

    def refuse(token):
        raise ValueError(f"{token} is not JSON")

    strict = lambda text: json.loads(text, parse_constant=refuse)  # noqa: E731
    assert strict((tmp_path / "metrics.jsonl").read_text()) == {
        "step": 1,
        "loss": None,
        "grad_norm": 2.5,
        "lr": [None, None],
    }
    assert strict((tmp_path / "metrics.json").read_text()) == {"tse": None, "clips": {"a": {"cse": 1.0}}}


def test_a_symlinked_log_is_refused_and_the_file_it_points_to_is_untouched(tmp_path):
    outside = tmp_path / "outside.txt"
    outside.write_text("someone's file\n")
    run = tmp_path / "run"
    run.mkdir()
    (run / "metrics.jsonl").symlink_to(outside)
    with pytest.raises(DrivewmError, match=r"metrics\.jsonl: is a symlink"):
        JsonlAppender(run / "metrics.jsonl")
    assert outside.read_text() == "someone's file\n"


def test_a_symlink_inside_an_output_folder_is_not_followed_out_of_it(tmp_path):
    """The output folder, resolved once where --out is parsed (drivewm.paths.confine_to): a folder symlinked
    inside it (``RUN/samples -> elsewhere``) is refused for writing, while the output folder itself may be a
    symlink the user made, and a symlink at a final name is replaced, never written through."""
    from drivewm.paths import confine_to

    elsewhere, real_run = tmp_path / "elsewhere", tmp_path / "disk" / "run"
    elsewhere.mkdir()
    real_run.mkdir(parents=True)
    (tmp_path / "run").symlink_to(real_run)  # the user's --out: a link to another disk
    run = tmp_path / "run"
    confine_to(run)
    (run / "samples").symlink_to(elsewhere)
    write_bytes(run / "config.json", b"{}")  # through the user's own link: fine
    with pytest.raises(DrivewmError, match=r"samples/step_1\.png: a symlink inside .* leads out of it"):
        write_bytes(run / "samples" / "step_1.png", b"png")
    with pytest.raises(DrivewmError, match="leads out of it"):
        JsonlAppender(run / "samples" / "metrics.jsonl")
    (run / "report.json").symlink_to(elsewhere / "report.json")
    write_bytes(run / "report.json", b"{}")
    assert not (run / "report.json").is_symlink() and list(elsewhere.iterdir()) == []
    assert (real_run / "config.json").read_bytes() == b"{}"
