"""Curation throughput in camera-frames/s against the raw decode rate of the same logs (the
practical limit: curation must at least decode every JPEG once), and the local executor's
speed-up from 1 to 2 workers. All three are measured in this run, on the same input.

    python benchmarks/bench_curate.py            # 4 simulated nuscenes6 drives of 4 s (small)
    python benchmarks/bench_curate.py --full     # 8 drives of 10 s
    python benchmarks/bench_curate.py --logs DIR # your own MCAP logs
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path

os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")


def simulate_logs(out: Path, drives: int, duration_s: float) -> list[Path]:
    from drivewm.sim import SimConfig, simulate

    scenarios = ["highway", "roundabout", "merge", "intersection"]
    return [
        simulate(
            SimConfig(source="highway", scenario=scenarios[i % 4], rig="nuscenes6", duration_s=duration_s, seed=i),
            out / f"drive{i}.mcap",
        )
        for i in range(drives)
    ]


def decode_rate(logs: list[Path]) -> tuple[int, float, float]:
    """(camera frames, seconds to read every log and decode every image once, seconds to encode
    those frames as 17-frame H.264 clips with drivewm.clips.video.encode_mp4)."""
    import numpy as np

    from drivewm.clips.video import encode_mp4
    from drivewm.logs.reader import read_log

    start, frames, decoded = time.perf_counter(), 0, []
    for path in logs:
        log = read_log(path)
        for cam_frames in log.images.values():
            decoded.append(np.stack([f.decode() for f in cam_frames]))
            frames += len(cam_frames)
    t_decode = time.perf_counter() - start
    start = time.perf_counter()
    for video in decoded:
        for i in range(0, len(video) - 16, 17):
            encode_mp4(video[i : i + 17], 10.0)
    encoded = sum((len(v) // 17) * 17 for v in decoded)
    return frames, t_decode, (time.perf_counter() - start) * frames / max(encoded, 1)


def curate_time(logs: list[Path], out: Path, workers: int) -> tuple[float, int]:
    from drivewm.curate import curate, load_curate_config

    cfg = load_curate_config("default")
    start = time.perf_counter()
    report = curate(logs, out, cfg, executor="local", workers=workers, progress=False)
    return time.perf_counter() - start, report["kept"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--full", action="store_true", help="8 drives of 10 s instead of 4 of 4 s")
    parser.add_argument("--logs", type=Path, help="benchmark these MCAP logs instead of simulating")
    args = parser.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_curate_"))
    try:
        if args.logs:
            logs = sorted(args.logs.glob("*.mcap"))
        else:
            drives, duration = (8, 10.0) if args.full else (4, 4.0)
            print(f"simulating {drives} nuscenes6 drives of {duration:.0f} s ...")
            logs = simulate_logs(tmp / "logs", drives, duration)
        frames, t_decode, t_encode = decode_rate(logs)
        t1, kept = curate_time(logs, tmp / "out1", workers=1)
        t2, kept2 = curate_time(logs, tmp / "out2", workers=2)
        assert kept == kept2, "1 and 2 workers must keep the same clips"
        print(f"input: {len(logs)} logs, {frames} camera frames; kept {kept} clips")
        print(f"raw decode (read_log + JPEG decode): {frames / t_decode:8.1f} camera-frames/s")
        print(f"H.264 encode only (encode_mp4):     {frames / t_encode:8.1f} camera-frames/s  (the other fixed cost)")
        print(
            f"curate, local, 1 worker:            {frames / t1:8.1f} camera-frames/s  = {t_decode / t1:.2f} x raw "
            "decode"
        )
        print(
            f"curate, local, 2 workers:           {frames / t2:8.1f} camera-frames/s  = {t_decode / t2:.2f} x raw "
            "decode"
        )
        print(f"speed-up 1 -> 2 workers: {t1 / t2:.2f} x (on {os.cpu_count()} CPUs)")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
