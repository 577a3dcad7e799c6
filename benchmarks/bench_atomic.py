"""What durability costs: drivewm.atomic writes with fsync (the default) against the same atomic
writes without it (``durable=False``: temp name + rename only) and a plain ``open().write()``, for
the file sizes the stages write (a clip JSON, a per-camera mp4, a shard, a model checkpoint).

Each round writes every size once with each method, interleaved, and the medians over rounds are
compared in the same run, so a loaded machine slows all methods alike.

    python benchmarks/bench_atomic.py               # 9 rounds
    python benchmarks/bench_atomic.py --rounds 40
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

from drivewm.atomic import atomic_path

SIZES = {"clip json 2 KB": 2_000, "camera mp4 200 KB": 200_000, "shard 8 MB": 8_000_000, "checkpoint 32 MB": 32_000_000}


def plain(path: Path, data: bytes) -> None:
    with open(path, "wb") as f:
        f.write(data)


def atomic_only(path: Path, data: bytes) -> None:
    with atomic_path(path, durable=False) as tmp:
        tmp.write_bytes(data)


def durable(path: Path, data: bytes) -> None:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


METHODS = {"plain write": plain, "atomic, no fsync": atomic_only, "atomic + fsync (default)": durable}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--dir", type=Path, default=None, help="folder on the disk to measure (default: a temp folder)")
    args = parser.parse_args()
    payload = {name: os.urandom(size) for name, size in SIZES.items()}
    times: dict[tuple[str, str], list[float]] = {(s, m): [] for s in SIZES for m in METHODS}
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        for r in range(args.rounds):
            for size in SIZES:
                for method, write in METHODS.items():
                    path = Path(tmp) / f"{method[:6]}-{r}.bin"
                    tic = time.perf_counter()
                    write(path, payload[size])
                    times[size, method].append(time.perf_counter() - tic)
                    path.unlink()
    print(f"median seconds per write over {args.rounds} interleaved rounds (ratio to 'atomic, no fsync'):")
    for size in SIZES:
        base = statistics.median(times[size, "atomic, no fsync"])
        cells = [
            f"{m} {statistics.median(times[size, m]) * 1e3:8.2f} ms ({statistics.median(times[size, m]) / base:5.2f}x)"
            for m in METHODS
        ]
        print(f"  {size:18s} " + " | ".join(cells))


if __name__ == "__main__":
    main()
