"""Issue 15, curation and import: two logs one name (item 2), concurrent runs on one folder (item 3),
pool workers after a killed parent (item 5), cameras without images or calibration (item 6), a
singular K (item 7), and import-video skipping bad videos with warnings on the console (item 10)."""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import tarfile
import time
import types
from pathlib import Path

import numpy as np
import pytest

import drivewm
from drivewm.cli import main
from drivewm.clips import read_manifest
from drivewm.curate import curate, load_curate_config
from drivewm.geometry import Rig
from drivewm.logs import writer as log_writer

sys.path.insert(0, str(Path(__file__).parent))
from synth import make_log, write_synth_log  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
CONFIG = "test"
CODE = Path(drivewm.__file__).resolve().parents[1]  # subprocesses run the drivewm under test
ENV = {**os.environ, "PYTHONPATH": str(CODE)}


def shard_keys(out: Path) -> dict[str, list[str]]:
    """Clip keys per shard file, read from the tar members."""
    keys = {}
    for shard in sorted(out.glob("*.tar")):
        with tarfile.open(shard) as tar:
            keys[shard.name] = sorted({m.name.partition(".")[0] for m in tar})
    return keys


def assert_consistent(out: Path) -> list[str]:
    """Every manifest row's clip is in its shard, every shard clip is in the manifest, once."""
    rows = read_manifest(out)
    in_shards = shard_keys(out)
    for row in rows:
        assert row["key"] in in_shards.get(row["shard"], []), (row["key"], row["shard"], sorted(in_shards))
    all_keys = [k for keys in in_shards.values() for k in keys]
    assert sorted(all_keys) == sorted(r["key"] for r in rows)
    assert len(set(all_keys)) == len(all_keys), "a key in two shards"
    return sorted(all_keys)


# ----------------------------------------------------------------------------- item 2


def test_same_log_twice_and_colliding_stems_keep_every_shard(tmp_path):
    a = write_synth_log(tmp_path / "logs" / "drive a.mcap", seed=1, n_frames=36)
    b = write_synth_log(tmp_path / "logs" / "drive_a.mcap", seed=2, n_frames=36)
    report = curate([a, a, b], tmp_path / "out", load_curate_config(CONFIG), progress=False)
    names = sorted(report["logs"])
    assert len(names) == 2 and names[0] != names[1] and all(n.startswith("drive_a") for n in names), names
    assert report["dropped"].get("near_duplicate_across_logs", 0) == 0
    assert report["warnings"] == [f"{a}: given twice (as {a}); used once"]
    keys = assert_consistent(tmp_path / "out")
    assert len(keys) == report["kept"] == 4  # 36 ticks -> 2 clips of 17 per log


# ----------------------------------------------------------------------------- item 3


@pytest.mark.slow  # two curate processes, about 20 s
def test_a_second_run_on_the_same_folder_is_refused_and_the_first_completes(tmp_path):
    # enough input that the first run is still curating when the second starts, on a fast machine too
    logs = [write_synth_log(tmp_path / "logs" / f"d{i}.mcap", seed=10 + i, n_frames=36) for i in range(12)]
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "drivewm.cli", "curate", *map(str, logs), "--out", str(out), "--recipe", CONFIG]
    first = subprocess.Popen(cmd, cwd=CODE, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        start = time.time()
        while not (out / "logs").is_dir() and first.poll() is None and time.time() - start < 120:
            time.sleep(0.05)  # the first run is inside curation (it made OUT/logs) before the second starts
        assert first.poll() is None, "the first run ended before the second could start"
        second = subprocess.run(
            [*cmd, "--set", "clips_per_shard=1"], cwd=CODE, env=ENV, capture_output=True, text=True, timeout=300
        )
    finally:
        _, first_err = first.communicate(timeout=600)
    assert first.returncode == 0, first_err[-2000:]
    assert second.returncode == 2 and "another curate run" in second.stderr, second.stderr[-2000:]
    assert f"pid {first.pid}" in second.stderr
    assert len(assert_consistent(out)) == 24
    assert all(len(keys) == 2 for keys in shard_keys(out).values())  # the first run's clips_per_shard (8)


# ----------------------------------------------------------------------------- item 5


def _descendants(pid: int) -> list[int]:
    """The pool's processes under ``pid``: its fork server and the workers forked from it (not the
    resource tracker, which is not the pool's)."""
    import psutil

    try:
        kids = psutil.Process(pid).children(recursive=True)
        return [c.pid for c in kids if "resource_tracker" not in " ".join(c.cmdline())]
    except psutil.NoSuchProcess:
        return []


@pytest.mark.slow  # a curate process and its pool, about 20 s
def test_pool_workers_exit_when_the_parent_is_killed(tmp_path):
    import psutil

    logs = [write_synth_log(tmp_path / "logs" / f"w{i}.mcap", seed=20 + i, n_frames=36) for i in range(4)]
    cmd = [sys.executable, "-m", "drivewm.cli", "curate", *map(str, logs), "--out", str(tmp_path / "out")]
    parent = subprocess.Popen([*cmd, "--recipe", CONFIG, "--workers", "2"], cwd=CODE, env=ENV)
    workers: list[int] = []
    try:
        start = time.time()
        while time.time() - start < 120 and parent.poll() is None:
            workers = _descendants(parent.pid)
            if len(workers) >= 3:  # the fork server and two workers
                break
            time.sleep(0.05)
        assert len(workers) >= 3, "the pool did not start"
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait()
        watched = []
        for pid in workers:
            try:
                watched.append(psutil.Process(pid))
            except psutil.NoSuchProcess:  # exited already, between the kill and this line: what is asked
                pass
        gone, alive = psutil.wait_procs(watched, timeout=15)
        assert not alive, f"workers {[p.pid for p in alive]} outlived their killed parent"
    finally:
        for pid in workers:  # the test's own processes, should any survive
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


# ----------------------------------------------------------------------------- items 6 and 7


def _write_patched(path: Path, log, monkeypatch, phantom: str | None = None, singular: str | None = None) -> Path:
    """Write ``log`` with the SDK writer, its metadata also listing a camera ``phantom`` that gets no
    calibration and no image, and/or camera ``singular`` calibrated with K = diag(0, 0, 1)."""
    real_open, real_calibration = log_writer.LogWriter._open, log_writer.LogWriter._calibration_msg

    def _open(self, tmp):
        rig = self.rig
        if phantom:
            self.rig = Rig(rig.name, rig.cameras + [dataclasses.replace(rig.cameras[0], name=phantom)])
        try:
            real_open(self, tmp)
        finally:
            self.rig = rig

    def _calibration(self, cam, timestamp_ns):
        if cam.name == singular:  # the SDK writes any K: only Camera() refuses it, so pass a stand-in
            cam = types.SimpleNamespace(**{**vars(cam), "K": np.diag([0.0, 0.0, 1.0])})
        return real_calibration(self, cam, timestamp_ns)

    with monkeypatch.context() as m:
        m.setattr(log_writer.LogWriter, "_open", _open)
        m.setattr(log_writer.LogWriter, "_calibration_msg", _calibration)
        return log_writer.write_log(log, path)


def test_camera_problems_are_named_and_the_good_log_is_kept(tmp_path, monkeypatch, capsys):
    folder = tmp_path / "logs"
    folder.mkdir()
    no_images = write_synth_log(folder / "no_images.mcap", seed=31, n_frames=36, drop={"CAM_FRONT_RIGHT": range(36)})
    phantom = _write_patched(folder / "phantom.mcap", make_log("x", seed=32, n_frames=36), monkeypatch, phantom="CAM_X")
    singular = _write_patched(
        folder / "singular.mcap", make_log("x", 33, n_frames=36), monkeypatch, singular="CAM_FRONT"
    )
    rc = main(
        ["curate", str(no_images), str(phantom), str(singular), "--out", str(tmp_path / "out"), "--recipe", CONFIG]
    )
    err = capsys.readouterr().err
    assert rc == 0
    report = load_report(tmp_path / "out")
    failed = {name: log["error"] for name, log in report["logs"].items() if log["status"] == "failed"}
    assert failed == {
        "no_images": f"{no_images}: camera(s) ['CAM_FRONT_RIGHT'] have a calibration but no images; "
        "curate the others with cameras=[...]",
        "singular": f"{singular}: camera 'CAM_FRONT': K is singular or flipped (fx=0, fy=0; both must be > 0)",
    }
    phantom_log = report["logs"]["phantom"]
    assert phantom_log["status"] == "ok" and phantom_log["kept"] == 2
    note = "the log's metadata lists camera(s) ['CAM_X'] but it has no calibration or images for them"
    assert note in phantom_log["warnings"]
    assert f"warning: phantom: {note}" in err  # per-log warnings reach the console, not only report.json
    assert {
        r["cameras"] == ["CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT"] for r in read_manifest(tmp_path / "out")
    } == {True}
    again = curate(
        [no_images],
        tmp_path / "out2",
        load_curate_config(CONFIG, ["cameras=[CAM_FRONT_LEFT,CAM_FRONT]"]),
        progress=False,
    )
    assert again["logs"]["no_images"]["status"] == "ok" and again["kept"] == 2


def load_report(out: Path) -> dict:
    import json

    return json.loads((out / "report.json").read_text())


def test_nothing_kept_is_a_batch_error_with_a_line_per_log(tmp_path, capsys):
    (tmp_path / "bad.mcap").write_text("not a log")
    short = write_synth_log(tmp_path / "short.mcap", seed=40, n_frames=10)  # shorter than one clip
    rc = main(["curate", str(tmp_path / "bad.mcap"), str(short), "--out", str(tmp_path / "out"), "--recipe", CONFIG])
    err = capsys.readouterr().err.splitlines()
    err = err[next(i for i, line in enumerate(err) if line.startswith("error:")) :]
    assert rc == 2 and err[0] == "error: curate: no clip kept from 2 log(s)"
    assert err[1].startswith("  bad: ") and "bad.mcap" in err[1] and err[2] == "  short: no clip kept (dropped {})"


# ----------------------------------------------------------------------------- item 7 (import) and 10


CALIBRATION = "name: dashcam\ncameras:\n  - {name: CAM_FRONT, width: 64, height: 48, %s, xyz: [1.5, 0.0, 1.3]}\n"


def _mp4(path: Path, frames: int = 12) -> Path:
    from drivewm.clips.video import encode_mp4

    yy, xx = np.mgrid[0:48, 0:64]
    video = np.stack([np.stack([xx * 3 + t, yy * 4, 0 * xx + 99], -1) for t in range(frames)]).astype(np.uint8)
    path.write_bytes(encode_mp4(video, 10.0))
    return path


def test_import_video_skips_bad_videos_and_refuses_a_singular_k(tmp_path, capsys):
    videos = tmp_path / "videos"
    videos.mkdir()
    good = _mp4(videos / "good drive.mp4")
    (videos / "broken.mp4").write_bytes(good.read_bytes()[: len(good.read_bytes()) // 3])
    (videos / "empty.mp4").write_bytes(b"")
    (tmp_path / "cam.yaml").write_text(CALIBRATION % "hfov_deg: 90")
    rc = main(
        ["import-video", str(videos), "--calibration", str(tmp_path / "cam.yaml"), "--out", str(tmp_path / "logs")]
    )
    out, err = capsys.readouterr()
    assert rc == 0 and sorted(p.name for p in (tmp_path / "logs").iterdir()) == ["good_drive.mcap"]
    assert out.strip() == str(tmp_path / "logs" / "good_drive.mcap")
    assert f"warning: skipped {videos / 'broken.mp4'}: cannot decode video" in err
    assert f"warning: skipped {videos / 'empty.mp4'}: cannot decode video" in err

    (tmp_path / "cam.yaml").write_text(CALIBRATION % "K: [[0, 0, 0], [0, 0, 0], [0, 0, 1]]")
    rc = main(["import-video", str(good), "--calibration", str(tmp_path / "cam.yaml"), "--out", str(tmp_path / "o2")])
    message = "camera 'CAM_FRONT': K is singular or flipped (fx=0, fy=0; both must be > 0)"
    assert rc == 2 and capsys.readouterr().err == f"error: {tmp_path / 'cam.yaml'}: {message}\n"

    (tmp_path / "cam.yaml").write_text(CALIBRATION % "hfov_deg: 90")
    rc = main(
        [
            "import-video",
            str(videos / "broken.mp4"),
            str(videos / "empty.mp4"),
            "--calibration",
            str(tmp_path / "cam.yaml"),
            "--out",
            str(tmp_path / "o3"),
        ]
    )
    err = capsys.readouterr().err.splitlines()
    err = err[next(i for i, line in enumerate(err) if line.startswith("error:")) :]
    assert rc == 2 and err[0] == "error: import-video: no video could be imported (2 failed)" and len(err) == 3
    assert not (tmp_path / "o3").exists() or not any((tmp_path / "o3").iterdir())


def test_clock_jumping_back_is_warned_on_the_console(tmp_path, capsys):
    log = make_log("x", seed=50, n_frames=40)
    cam = "CAM_FRONT"
    frames = log.images[cam]
    jump = frames[20].timestamp_ns - frames[5].timestamp_ns  # from frame 20 on, the clock reads 1.5 s earlier
    log.images[cam] = frames[:20] + [dataclasses.replace(f, timestamp_ns=f.timestamp_ns - jump) for f in frames[20:]]
    path = _write_in_order(tmp_path / "jump.mcap", log)
    rc = main(["curate", str(path), "--out", str(tmp_path / "out"), "--recipe", CONFIG])
    err = capsys.readouterr().err
    assert rc == 0
    warnings = load_report(tmp_path / "out")["logs"]["jump"]["warnings"]
    assert warnings and all(f"warning: jump: {w}" in err for w in warnings)
    assert warnings == [
        "CAM_FRONT: 15 duplicated timestamps (kept the first)",
        "CAM_FRONT: starts 0.00 s late and stops 1.50 s early; clips cover only the common span",
    ]


def _write_in_order(path: Path, log) -> Path:
    return log_writer.write_log(log, path)
