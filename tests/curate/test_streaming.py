"""The streaming stage: windows equal the batch split, ticks assemble from out-of-order frames,
and peak memory does not grow with the log's length."""

import json
import subprocess
import sys
from pathlib import Path

import av
import cv2
import numpy as np
import pytest

from drivewm.curate.sync import synchronize
from drivewm.curate.ticks import TickAssembler
from drivewm.curate.windows import WindowStream
from drivewm.logs.types import ImageFrame

sys.path.insert(0, str(Path(__file__).parent))
from batch_split import clip_windows, shot_boundaries, split_segment  # noqa: E402
from synth import write_long_log  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
MS = 1_000_000


@pytest.fixture(scope="module")
def sintel_frames(shared_data):
    """The 30 s Sintel trailer clip with 6 hard cuts, 320 px wide (what the shot detector sees)."""
    with av.open(str(shared_data / "video/sintel_cuts/test_video_30s.mp4")) as container:
        return [
            cv2.resize(f.to_ndarray(format="rgb24"), (320, 180), interpolation=cv2.INTER_AREA)
            for f in container.decode(video=0)
        ]


def _batch_windows(frames, runs, T, stride, threshold=2.5, min_frames=3):
    segments = []
    for a, b in runs:
        cuts = [a + c for c in shot_boundaries(frames[a:b], 24.0, threshold, min_frames)]
        segments += split_segment(a, b, cuts)
    return clip_windows(segments, T, stride), segments


@pytest.mark.parametrize("T,stride", [(17, 17), (9, 5), (5, 12)])
def test_streamed_windows_equal_the_batch_split(sintel_frames, T, stride):
    runs = [(0, 300), (302, 340), (345, 720)]  # gaps between valid runs, as dropped frames leave
    want, segments = _batch_windows(sintel_frames, runs, T, stride)
    assert len(segments) >= len(runs) + 5, "the clip's hard cuts must split the runs"
    stream = WindowStream(runs, T, stride, 24.0, 2.5, 3, np.zeros((180, 320, 3), np.uint8))
    got, held = [], 0
    for a, b in runs:
        for t in range(a, b):
            got += stream.push(t, lambda t=t: sintel_frames[t])
            held = max(held, t + 1 - stream.oldest_needed)
    assert got == want
    assert held <= T + 3  # a window, plus the detector's look-ahead of 2 frames


def test_ticks_assemble_from_out_of_order_and_duplicated_frames():
    t = np.arange(10) * 100 * MS
    cams = {"A": t, "B": t + 3 * MS}
    table = synchronize(cams, ["A", "B"], 100 * MS, 25 * MS)
    needed = np.ones(10, bool)
    needed[4] = False  # a tick no clip uses is never parked
    asm = TickAssembler(table, {c: np.sort(v) for c, v in cams.items()}, needed)
    arrivals = [("A", i) for i in range(10)] + [("B", i) for i in (1, 0, 3, 2, 5, 4, 7, 6, 9, 8)]
    arrivals.insert(3, ("B", 0))  # B's first frame early...
    arrivals.append(("B", 0))  # ... and a second frame at the same stamp: the first keeps it
    released = []
    for cam, i in arrivals:
        frame = ImageFrame(int(cams[cam][i]), f"{cam}{i}-{len(released)}".encode())
        for tick, frames in asm.add(cam, frame):
            released.append((tick, [f.data.decode().split("-")[0] for f in frames]))
    asm.finish("test")
    assert [r[0] for r in released] == [0, 1, 2, 3, 5, 6, 7, 8, 9]
    assert released[0][1] == ["A0", "B0"] and all(r[1] == [f"A{r[0]}", f"B{r[0]}"] for r in released)


RSS_SCRIPT = """
import json, resource, sys
from drivewm.curate import curate, load_curate_config
cfg = load_curate_config(sys.argv[3])
report = curate([sys.argv[1]], sys.argv[2], cfg, progress=False)
log = next(iter(report["logs"].values()))
print(json.dumps({"rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "kept": report["kept"],
                  "frames": log["camera_frames"], "status": log["status"]}))
"""


@pytest.mark.slow
def test_peak_memory_does_not_grow_with_log_length(tmp_path):
    """30 s and 180 s of a 6-camera log (~25 and ~150 MB of JPEG): reading the whole log would add
    the difference to the peak; streaming holds a clip window either way."""
    runs = {}
    for seconds in (30, 180):
        log = write_long_log(tmp_path / f"long{seconds}.mcap", seconds=seconds, moving_s=6.0)
        proc = subprocess.run(
            [
                sys.executable,
                "-c",
                RSS_SCRIPT,
                str(log),
                str(tmp_path / f"out{seconds}"),
                "test",
            ],
            capture_output=True,
            text=True,
            timeout=600,
            env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
        )
        assert proc.returncode == 0, proc.stderr[-2000:]
        runs[seconds] = json.loads(proc.stdout.strip().splitlines()[-1])
    short, long = runs[30], runs[180]
    assert short["status"] == long["status"] == "ok" and short["kept"] == long["kept"] == 4  # the moving 6 s
    assert long["frames"] == 6 * short["frames"]
    log_mb = (tmp_path / "long180.mcap").stat().st_size / 2**20
    assert log_mb > 100
    grown = long["rss_mb"] - short["rss_mb"]
    assert grown < 0.1 * log_mb, (
        f"peak RSS grew {grown:.0f} MB from 30 s to 180 s ({short['rss_mb']:.0f} MB -> {long['rss_mb']:.0f} MB)"
    )
