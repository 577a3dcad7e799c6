"""Drive-log write/read throughput, as ratios against peers measured in the same run.

Write: ``LogWriter.write_images`` (JPEG encode + Foxglove SDK MCAP) against JPEG encoding alone
(cv2.imencode, the floor any writer pays). Read: ``read_log`` (protobuf decode + assembly into a
DriveLog) against raw ``mcap`` iteration of the same file (no decoding). Ratios near 1 mean the
MCAP/protobuf layers cost little beyond the unavoidable work.

    python benchmarks/bench_logs.py            # nuscenes6 at 320x192, 3 s at 10 fps (180 images)
    python benchmarks/bench_logs.py --full     # nuscenes6 at 640x360, 20 s at 10 fps (1200 images)
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np


def _frames(rig, ticks: int, seed: int = 0) -> list[dict[str, np.ndarray]]:
    """Textured frames (smooth gradients + grain, so JPEG sizes are realistic)."""
    rng = np.random.default_rng(seed)
    out = []
    for t in range(ticks):
        frame = {}
        for k, cam in enumerate(rig.cameras):
            yy, xx = np.mgrid[0 : cam.height, 0 : cam.width]
            base = np.stack([(xx + 3 * t) % 256, (yy + 20 * k) % 256, (xx + yy) // 2 % 256], -1)
            frame[cam.name] = np.clip(base + rng.integers(-12, 12, base.shape), 0, 255).astype(np.uint8)
        out.append(frame)
    return out


def _timed(fn, repeats: int = 2) -> float:
    """Best of ``repeats`` runs (the first also pays one-off imports)."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--full", action="store_true", help="640x360, 20 s (default: 320x192, 3 s)")
    args = parser.parse_args()

    from mcap.reader import make_reader

    from drivewm.geometry import T_from_xyz_yaw, load_rig
    from drivewm.logs.reader import read_log
    from drivewm.logs.types import SceneInfo
    from drivewm.logs.writer import LogWriter, encode_image

    width, height, seconds = (640, 360, 20.0) if args.full else (320, 192, 3.0)
    rig = load_rig("nuscenes6").scaled(width, height, fit="stretch")
    ticks = int(seconds * 10)
    frames = _frames(rig, ticks)
    n_images = ticks * len(rig.cameras)
    path = Path(tempfile.mkdtemp()) / "bench.mcap"

    def encode_only():
        for frame in frames:
            for image in frame.values():
                encode_image(image)

    def write():
        with LogWriter(path, rig, SceneInfo({"source": "bench"})) as w:
            for t, frame in enumerate(frames):
                ts = t * 100_000_000
                w.write_pose(ts, T_from_xyz_yaw(t * 1.5, 0.0, 0.0, 0.01 * t))
                w.write_images(ts, frame)

    def raw_iterate():
        with open(path, "rb") as f:
            for _ in make_reader(f).iter_messages():
                pass

    t_encode, t_write = _timed(encode_only), _timed(write)
    t_raw, t_read = _timed(raw_iterate), _timed(lambda: read_log(path))
    size_mb = path.stat().st_size / 1e6
    print(f"nuscenes6 {width}x{height}, {ticks} ticks, {n_images} images, file {size_mb:.1f} MB")
    print(
        f"write: LogWriter {n_images / t_write:8.1f} images/s | JPEG encode alone {n_images / t_encode:8.1f} images/s"
        f" | ratio writer/encode time {t_write / t_encode:.2f}"
    )
    print(
        f"read:  read_log  {n_images / t_read:8.1f} images/s | raw mcap iteration {n_images / t_raw:8.1f} images/s"
        f" | ratio read_log/raw time {t_read / t_raw:.2f}"
    )
    print(
        f"real-time factor at 10 fps x 6 cameras: write {n_images / t_write / 60:.1f}x, "
        f"read {n_images / t_read / 60:.1f}x"
    )


if __name__ == "__main__":
    main()
