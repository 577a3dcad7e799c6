"""One curation run over good and bad synthetic MCAP logs; resume after SIGKILL; Ray == local."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from drivewm.clips import iter_clips, read_manifest
from drivewm.curate import balanced_sample, curate, load_curate_config
from drivewm.logs.reader import read_log

sys.path.insert(0, str(Path(__file__).parent))
from synth import write_synth_log  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
CONFIG = "test"


def make_logs(folder: Path) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    logs = [
        write_synth_log(folder / "good_a.mcap", seed=1, n_frames=52),
        write_synth_log(
            folder / "good_b.mcap",
            seed=2,
            n_frames=52,
            jitter_ns=8_000_000,
            tags={
                "weather": "snow",
                "time_of_day": "day",
                "road_type": "highway",
                "traffic_density": "low",
                "source": "synthetic",
            },
        ),
        write_synth_log(folder / "cam_drops.mcap", seed=3, n_frames=52, drop={"CAM_FRONT_RIGHT": [20, 21, 22]}),
        write_synth_log(folder / "nan_pose.mcap", seed=4, n_frames=52, nan_poses=[7, 8, 30]),
        write_synth_log(folder / "corrupt_jpeg.mcap", seed=6, n_frames=52, corrupt={"CAM_FRONT_LEFT": [25]}),
    ]
    trunc = write_synth_log(folder / "truncated.mcap", seed=5, n_frames=52)
    data = trunc.read_bytes()
    trunc.write_bytes(data[: len(data) // 2])
    (folder / "not_mcap.mcap").write_text("this is a text file, not a drive log\n")
    return logs + [trunc, folder / "not_mcap.mcap"]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("curate")
    logs = make_logs(root / "logs")
    cfg = load_curate_config(CONFIG)
    report = curate(logs, root / "out", cfg, progress=False)
    return root, logs, cfg, report


def test_bad_logs_reported_and_good_logs_curated(run):
    root, logs, cfg, report = run
    by = report["logs"]
    assert by["truncated"]["status"] == "failed" and "truncat" in by["truncated"]["error"].lower()
    assert by["not_mcap"]["status"] == "failed" and "not_mcap.mcap" in by["not_mcap"]["error"]
    assert "mcap" in by["not_mcap"]["error"].lower()
    for name in ("good_a", "good_b", "cam_drops", "nan_pose", "corrupt_jpeg"):
        assert by[name]["status"] == "ok" and by[name]["kept"] >= 1, (name, by[name])
    assert by["corrupt_jpeg"]["dropped"] == {"undecodable_frame": 1} and by["corrupt_jpeg"]["kept"] == 2
    assert by["good_a"]["kept"] == 3  # 52 ticks -> 3 clips of 17
    assert any("CAM_FRONT_RIGHT: 3 of" in w for w in by["cam_drops"]["warnings"])
    assert by["cam_drops"]["kept"] == 2  # the gap at ticks 20-22 leaves [0, 20) and [23, 52): one clip each
    assert any("3 NaN/missing bridged" in w for w in by["nan_pose"]["warnings"])
    assert report["worst_sync_skew_ns"] == 8_000_000  # good_b's jittered rig
    assert report["logs_failed"] == 2 and report["kept"] == len(read_manifest(root / "out"))
    assert (root / "out" / "contact_sheet.png").stat().st_size > 10_000


def test_clips_complete_synced_and_posed(run):
    root, logs, cfg, report = run
    clips = list(iter_clips(root / "out"))
    assert len(clips) == report["kept"]
    logged = {Path(p).stem: read_log(p) for p in logs[:5]}
    for clip in clips:
        meta = clip.meta
        assert meta.cameras == ["CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT"]
        assert meta.num_frames == cfg.clip_frames and clip.videos().shape[:2] == (3, cfg.clip_frames)
        assert meta.sync_error_ns <= cfg.sync_tolerance_ms * 1e6
        assert len(meta.trajectory_ego) == cfg.trajectory_waypoints and abs(meta.trajectory_dt_s - 0.1) < 1e-9
        assert "CAM_FRONT_LEFT" in meta.view_captions and "front-left" in meta.view_captions["CAM_FRONT_LEFT"]
        log = logged[Path(meta.source_log).stem]
        idx = np.searchsorted(log.pose_timestamps_ns, meta.timestamps_ns)
        truth = log.T_world_from_ego[idx]
        ok = np.isfinite(truth).all(axis=(1, 2))
        # smoothing error bound on these exact poses: 5 cm (the filter trusts 0.3 m fixes, the motion is smooth)
        assert np.abs(clip.T_world_from_ego[ok, :3, 3] - truth[ok, :3, 3]).max() < 0.05
    assert max(c.meta.sync_error_ns for c in clips if "good_b" in c.key) == 8_000_000  # the jittered rig's worst skew


def test_rerun_skips_done_logs(run):
    root, logs, cfg, report = run
    before = {p.name: p.read_bytes() for p in (root / "out").glob("*.tar")}
    again = curate(logs, root / "out", cfg, progress=False)
    assert all(again["logs"][n].get("resumed") for n in ("good_a", "good_b", "cam_drops", "nan_pose", "corrupt_jpeg"))
    assert {p.name: p.read_bytes() for p in (root / "out").glob("*.tar")} == before


def test_balanced_sample_evens_out_weather(run):
    rows = read_manifest(run[0] / "out")
    sample = balanced_sample(rows, by="weather", n=4)
    weathers = [r["tags"]["weather"] for r in sample]
    assert sorted(weathers) == ["clear", "clear", "snow", "snow"]


def _wait_for(pattern_dir: Path, proc: subprocess.Popen, timeout: float = 120.0) -> None:
    start = time.time()
    while time.time() - start < timeout:
        if list(pattern_dir.glob("*.json")) or proc.poll() is not None:
            return
        time.sleep(0.01)


@pytest.mark.slow
def test_sigkill_then_rerun_equals_uninterrupted(run, tmp_path):
    root, logs, cfg, report = run
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "drivewm.cli", "curate", *map(str, logs), "--out", str(out), "--recipe", CONFIG]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _wait_for(out / "logs", proc)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (out / "manifest.jsonl").exists(), "the run finished before it could be killed"
    assert len(list((out / "logs").glob("*.json"))) < 5
    rerun = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert rerun.returncode == 0, rerun.stderr[-2000:]
    ref = root / "out"
    tars = sorted(p.name for p in ref.glob("*.tar"))
    assert sorted(p.name for p in out.glob("*.tar")) == tars
    for name in tars:
        assert (out / name).read_bytes() == (ref / name).read_bytes(), name
    assert (out / "manifest.jsonl").read_text() == (ref / "manifest.jsonl").read_text()
    assert not list(out.glob(".*.tmp"))


@pytest.mark.slow
def test_ray_executor_matches_local(run, tmp_path):
    pytest.importorskip("ray")
    root, logs, cfg, report = run
    ray_report = curate(logs, tmp_path / "out", cfg, executor="ray", workers=2, progress=False)
    assert ray_report["logs_failed"] == 2
    assert (tmp_path / "out" / "manifest.jsonl").read_text() == (root / "out" / "manifest.jsonl").read_text()


def test_same_drive_twice_is_deduplicated_across_logs(tmp_path):
    import shutil

    first = write_synth_log(tmp_path / "logs" / "drive_a.mcap", seed=7, n_frames=40)
    copy = tmp_path / "logs" / "drive_b.mcap"
    shutil.copy(first, copy)
    other = write_synth_log(tmp_path / "logs" / "drive_c.mcap", seed=8, n_frames=40)
    report = curate([copy, first, other], tmp_path / "out", load_curate_config(CONFIG), progress=False)
    assert report["duplicates_across_logs"] == {"drive_b-000000": "drive_a-000000", "drive_b-000017": "drive_a-000017"}
    assert report["dropped"] == {"near_duplicate_across_logs": 2}
    keys = sorted(c.key for c in iter_clips(tmp_path / "out"))
    assert keys == [
        "drive_a-000000",
        "drive_a-000017",
        "drive_c-000000",
        "drive_c-000017",
    ]  # pruned from the shards too
    assert keys == sorted(r["key"] for r in read_manifest(tmp_path / "out"))
