"""``drivewm eval compare``: eval outputs side by side with intervals, worst pairs drawn, ego paths plotted."""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import cv2
import numpy as np
import pytest

from drivewm.cli import main
from drivewm.clips import ShardWriter
from drivewm.clips.video import encode_mp4
from drivewm.eval.compare import clip_interval, worst_frame_pairs

FRONT_CAMERAS = ("CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT")


def _mp4_folder(root, videos: dict[str, np.ndarray], noise: float, clips: int = 2) -> None:
    """``clips`` folders of the three front views' first 2 frames, Gaussian noise of ``noise`` levels added."""
    rng = np.random.default_rng(0)
    for k in range(clips):
        for cam in FRONT_CAMERAS:
            v = videos[cam][:2]
            noisy = np.clip(v.astype(np.float32) + rng.normal(0, noise, v.shape), 0, 255).astype(np.uint8)
            (root / f"clip{k}").mkdir(parents=True, exist_ok=True)
            (root / f"clip{k}" / f"{cam}.mp4").write_bytes(encode_mp4(noisy, 10.0))


def _eval(location, out, *extra) -> None:
    args = ["eval", str(location), "--out", str(out), "--rig", "nuscenes6", "--no-pictures", *extra]
    assert main(args) == 0


def test_interval_over_clips_and_frame_pair_indexing():
    low, high, n = clip_interval([1.0, 2.0, 3.0, None, float("nan")])
    assert n == 3 and 1.0 <= low < 2.0 < high <= 3.0
    metrics = {
        "config": {"consistency": {"frame_gap": 1}},
        "clips": {"c": {"native_px_per_canonical_px": {"A": 1, "B": 1}, "tse_pair_medians": [0.1, 0.2, 0.9, 0.3]}},
    }
    worst = worst_frame_pairs(metrics, 1)[0]
    assert (worst["a"], worst["b"], worst["label"]) == (("B", 0), ("B", 1), "B frames 0-1")


def test_compare_page_from_recorded_metrics_says_what_it_cannot_draw(tmp_path):
    """Eval outputs without a recorded input (or whose input is gone) still compare: figures with
    intervals, worst pairs listed, and a note instead of pictures."""
    for name, values in (("a", [0.2, 0.4, 0.3]), ("b", [1.5, 2.5, 2.0])):
        clips = {
            f"c{i}": {"tse": v, "cse_pairs": ["X~Y"], "cse_pair_medians": [v], "tse_pair_medians": [v, v / 2],
                      "native_px_per_canonical_px": {"X": 1.0}}
            for i, v in enumerate(values)
        }  # fmt: skip
        (tmp_path / name).mkdir()
        (tmp_path / name / "metrics.json").write_text(json.dumps({"tse": float(np.mean(values)), "clips": clips}))
    assert main(["eval", "compare", str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(tmp_path / "o")]) == 0
    board = json.loads((tmp_path / "o" / "compare.json").read_text())
    a, b = next(r for r in board["figures"] if r["key"] == "tse")["cells"]
    assert a["high"] < b["low"] and a["n"] == b["n"] == 3
    assert [p["median_px"] for p in board["runs_detail"]["b"]["worst_camera_pairs"]] == [2.5, 2.0, 1.5]
    page = (tmp_path / "o" / "compare.html").read_text()
    assert page.count("records no input") == 4 and "<img" not in page


@pytest.mark.slow
def test_compare_two_generators_side_by_side(synth_videos, tmp_path, capsys):
    _mp4_folder(tmp_path / "clean", synth_videos, noise=0.0)
    _mp4_folder(tmp_path / "noisy", synth_videos, noise=40.0)
    for name in ("clean", "noisy"):
        _eval(tmp_path / name, tmp_path / f"run_{name}", "--metrics", "tse,cse")
    out = tmp_path / "board"
    assert main(["eval", "compare", str(tmp_path / "run_clean"), str(tmp_path / "run_noisy"), "--out", str(out)]) == 0
    page = (out / "compare.html").read_text()
    board = json.loads((out / "compare.json").read_text())
    tse = next(r for r in board["figures"] if r["key"] == "tse")
    clean, noisy = tse["cells"]
    assert clean["n"] == noisy["n"] == 2 and clean["low"] <= clean["value"] <= clean["high"]
    assert clean["value"] < noisy["value"]  # the noisy generator reads worse, beside the clean one
    assert re.search(r">tse</td><td>px</td><td>[0-9.]+ \[[0-9.e-]+, [0-9.e-]+\] <small>\(n=2 clips\)", page)
    for run in board["runs_detail"].values():
        pairs = run["worst_camera_pairs"] + run["worst_frame_pairs"]
        assert len(run["worst_camera_pairs"]) == len(run["worst_frame_pairs"]) == 3
        for p in pairs:  # every worst pair drawn from the re-read input, matches and all
            picture = cv2.imread(str(out / "compare_files" / p["picture"]))
            assert picture.shape == (192, 640, 3) and f"compare_files/{p['picture']}" in page
            verified, total = map(int, re.match(r"(\d+) of (\d+) verified", p["matches"]).groups())
            assert 0 < verified <= total
    medians = [p["median_px"] for p in board["runs_detail"]["run_noisy"]["worst_frame_pairs"]]
    assert medians == sorted(medians, reverse=True)
    assert page.count("no recovered ego path") == 2  # tse,cse only: nothing to plot, and it says so
    assert main(["eval", "compare", str(tmp_path / "clean"), "--out", str(tmp_path / "x")]) == 2
    assert "not an eval output (no metrics.json)" in capsys.readouterr().err


@pytest.mark.slow
def test_compare_plots_recovered_paths_against_logged_and_conditioned(synth_clip6, tmp_path):
    """End to end on a simulated clip with poses: structure from motion's ego path in trajectories.json,
    plotted on the page beside the logged path."""
    with ShardWriter(tmp_path / "clips", "sim", max_clips=2) as writer:
        writer.write(synth_clip6)
    assert main(["eval", str(tmp_path / "clips"), "--out", str(tmp_path / "run"), "--no-pictures"]) == 0
    paths = json.loads((tmp_path / "run" / "trajectories.json").read_text())[synth_clip6.meta.key]
    assert len(paths["recovered"]) == len(paths["recovered_frames"]) >= 3 and len(paths["reference"]) == 9
    travelled = np.linalg.norm(np.diff(np.asarray(paths["reference"])[:, :2], axis=0), axis=1).sum()
    assert travelled > 0.5  # the logged drive moves, so the plot has a path to compare against
    assert main(["eval", "compare", str(tmp_path / "run"), "--out", str(tmp_path / "board")]) == 0
    page = (tmp_path / "board" / "compare.html").read_text()
    assert "compare_files/run0_paths.png" in page and "no recovered ego path" not in page
    assert cv2.imread(str(tmp_path / "board" / "compare_files" / "run0_paths.png")).shape[0] > 100


@pytest.mark.slow
@pytest.mark.skipif(
    shutil.which("chromium") is None, reason="Debian's chromium is not installed (scripts/run-tests.sh installs it)"
)
def test_compare_page_loads_in_headless_chromium(tmp_path):
    """The page and its pictures as a real browser shows them: every picture decoded, the table present."""
    way = [[1.0 * (i + 1), 0.05 * (i + 1) ** 2, 0.0] for i in range(8)]
    recovered = [[0.0, 0.0, 0.0]] + [[0.5 * w[0], 0.5 * w[1], 0.0] for w in way]  # half scale: monocular
    trajectories = {"c0": {"fps": 10.0, "recovered_frames": list(range(9)), "recovered": recovered,
                           "conditioned": way, "conditioned_dt_s": 0.1}}  # fmt: skip
    run = tmp_path / "run"
    run.mkdir()
    (run / "metrics.json").write_text(json.dumps({"tse": 0.3, "clips": {"c0": {"tse": 0.3}}}))
    (run / "trajectories.json").write_text(json.dumps(trajectories))
    assert main(["eval", "compare", str(run), "--out", str(tmp_path / "o")]) == 0
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking"]
    dom = subprocess.run(
        ["chromium", *flags, f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=10000",
         "--dump-dom", (tmp_path / "o" / "compare.html").as_uri()],
        capture_output=True, text=True, timeout=120,
    ).stdout  # fmt: skip
    body = re.search(r'<body data-figures="(\d+)" data-figures-loaded="(\d+)"', dom)
    assert body, dom[:500]
    assert int(body.group(1)) == int(body.group(2)) == 1  # the ego-path plot
    assert '<table id="figures">' in dom and "run0_paths.png" in dom
