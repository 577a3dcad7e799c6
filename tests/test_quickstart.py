"""End to end: `drivewm quickstart --profile smoke` runs every stage through the public commands,
writes a report whose figures load in a real headless Chromium, and a rerun reuses every stage."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from drivewm.clips import iter_clips, read_manifest
from drivewm.quickstart import load_profile

pytestmark = pytest.mark.slow  # runs every stage of the pipeline (minutes)

CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def run_quickstart(out: Path) -> str:
    proc = subprocess.run(
        [sys.executable, "-m", "drivewm.cli", "quickstart", "--profile", "smoke", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=1500,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout


@pytest.fixture(scope="module")
def quickstart_dir(tmp_path_factory) -> tuple[Path, str]:
    out = tmp_path_factory.mktemp("quickstart")
    return out, run_quickstart(out)


def test_every_stage_ran_and_generated_clips_are_scored(quickstart_dir):
    out, stdout = quickstart_dir
    profile = load_profile("smoke")
    assert "expected about" in stdout  # says up front how long it will take
    clips = list(iter_clips(out / "clips"))
    assert clips and all(c.meta.cameras == clips[0].meta.cameras for c in clips)
    for g in profile.generations:
        generated = list(iter_clips(out / "generated" / g.name))
        assert generated, g.name
        assert generated[0].meta.cameras == clips[0].meta.cameras  # all six views generated
        assert generated[0].videos().shape[:2] == (len(clips[0].meta.cameras), clips[0].meta.num_frames)
        metrics = json.loads((out / "eval" / g.name / "metrics.json").read_text())
        assert "pose_success" in metrics and "tse" in metrics
    real = json.loads((out / "eval" / "real" / "metrics.json").read_text())
    assert real["tse"] is not None and 0 < real["tse"] < 2.0  # simulated clips are geometrically consistent
    tok = json.loads((out / "tokenizer_eval" / "metrics.json").read_text())
    assert tok["psnr"] > 8.0  # even 20 steps beat a constant grey image (about 6 dB on these renders)


def test_one_curated_clip_is_transferred_to_snow_with_its_labels_and_shown_in_the_report(quickstart_dir):
    out, _ = quickstart_dir
    source = next(iter_clips(out / "clips"))
    (done,) = list(iter_clips(out / "transfer"))  # --max-clips 1: the first curated clip
    assert done.meta.extra["transfer"]["source"]["key"] == source.key
    assert done.meta.cameras == source.meta.cameras and done.videos().shape[:2] == source.videos().shape[:2]
    assert done.meta.tags["weather"] == "snow" and done.meta.timestamps_ns == source.meta.timestamps_ns
    assert {r["pair_id"] for r in read_manifest(out / "paired_clips")} != {""}  # the model trained on pairs
    assert f"Transferred: {done.key}" in (out / "report.md").read_text()


def test_report_lists_real_and_generated_numbers(quickstart_dir):
    out, _ = quickstart_dir
    md = (out / "report.md").read_text()
    assert re.search(r"\| `tse` \| .* \| \d+\.\d+ \|", md)  # the real clips' TSE is a number
    assert "generated: snow_left" in md
    assert "drive.rrd" in md and (out / "drive.rrd").stat().st_size > 10_000


@pytest.mark.skipif(
    shutil.which("chromium") is None, reason="Debian's chromium is not installed (scripts/run-tests.sh installs it)"
)
def test_report_figures_load_in_headless_chromium(quickstart_dir, tmp_path):
    out, _ = quickstart_dir
    dom = subprocess.run(
        [
            "chromium",
            *CHROMIUM_FLAGS,
            f"--user-data-dir={tmp_path / 'profile'}",
            "--virtual-time-budget=10000",
            "--dump-dom",
            (out / "report.html").as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    ).stdout
    body = re.search(r'<body data-figures="(\d+)" data-figures-loaded="(\d+)"', dom)
    assert body, dom[:500]
    expected, loaded = int(body.group(1)), int(body.group(2))
    assert expected >= 4 and loaded == expected
    assert '<table id="eval-table">' in dom


def test_rerun_reuses_finished_stages(quickstart_dir):
    out, _ = quickstart_dir
    stdout = run_quickstart(out)
    stages = re.findall(r"\[quickstart\] (\S+): ", stdout)
    assert stages and all(f"[quickstart] {s}: done before, skipped" in stdout for s in stages)
