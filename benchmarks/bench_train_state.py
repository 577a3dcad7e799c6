"""What the checkpoint checks cost: saving and loading a training state with its digest and the kept
previous state (drivewm.train.checkpoint) against the same atomic, fsynced ``torch.save`` /
``torch.load(weights_only=True)`` without them (what it did before).

The state is shaped like the shared loop's (model, EMA, AdamW's two moments, RNG, step) for a
model of ``--params`` float32 parameters. Each round runs every method once, interleaved, and
the medians over rounds are compared in the same run, so a loaded machine slows all alike.

    python benchmarks/bench_train_state.py                    # 2M parameters (a 32 MB state), 7 rounds
    python benchmarks/bench_train_state.py --params 8000000 --rounds 5
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import torch

from drivewm.atomic import atomic_path
from drivewm.train.checkpoint import TRAIN_STATE_NAME, load_train_state, save_train_state


def make_state(params: int) -> dict:
    """A loop-shaped training state for ``params`` float32 parameters in 1024-wide matrices."""
    rows = max(1, params // 1024)
    names = [f"blocks.{i}.weight" for i in range(8)]
    model = {n: torch.randn(rows // 8 or 1, 1024) for n in names}
    optimizer = {
        "state": {
            i: {"step": torch.tensor(10.0), "exp_avg": t.clone(), "exp_avg_sq": t.abs()}
            for i, t in enumerate(model.values())
        },
        "param_groups": [{"lr": 1e-4, "betas": (0.9, 0.99), "params": list(range(len(names)))}],
    }
    ema = {n: t.clone() for n, t in model.items()}
    return {"model": model, "ema": ema, "optimizer": optimizer, "step": 10, "rng": {"torch": torch.get_rng_state()}}


def plain_save(folder: Path, state: dict) -> None:
    with atomic_path(folder / TRAIN_STATE_NAME) as tmp:
        torch.save(state, tmp)


def plain_load(folder: Path) -> dict:
    return torch.load(folder / TRAIN_STATE_NAME, map_location="cpu", weights_only=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--params", type=int, default=2_000_000)
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args()
    torch.set_num_threads(1)
    state = make_state(args.params)
    n = sum(t.numel() for t in state["model"].values())
    times: dict[str, list[float]] = {}  # wall seconds
    cpu_times: dict[str, list[float]] = {}  # this process's CPU seconds (less sensitive to a loaded machine)
    with tempfile.TemporaryDirectory() as tmp:
        plain_dir, checked_dir = Path(tmp) / "plain", Path(tmp) / "checked"
        methods = {
            "save: atomic torch.save": lambda: plain_save(plain_dir, state),
            "save: + digest, keep previous": lambda: save_train_state(checked_dir, state),
            "load: torch.load": lambda: plain_load(plain_dir),
            "load: + digest check": lambda: load_train_state(checked_dir),
        }
        for _ in range(args.rounds):
            for method, run in methods.items():
                tic, cpu = time.perf_counter(), time.process_time()
                run()
                times.setdefault(method, []).append(time.perf_counter() - tic)
                cpu_times.setdefault(method, []).append(time.process_time() - cpu)
        size_mb = (plain_dir / TRAIN_STATE_NAME).stat().st_size / 1e6
    print(f"training state of {n / 1e6:.1f}M parameters ({size_mb:.0f} MB file); medians of {args.rounds} rounds:")
    for kind, base in (("save", "save: atomic torch.save"), ("load", "load: torch.load")):
        ref, ref_cpu = statistics.median(times[base]), statistics.median(cpu_times[base])
        for method in (m for m in times if m.startswith(kind)):
            t, c = statistics.median(times[method]), statistics.median(cpu_times[method])
            print(
                f"  {method:32s} wall {t * 1e3:8.1f} ms ({t / ref:4.2f}x)   CPU {c * 1e3:7.1f} ms ({c / ref_cpu:4.2f}x)"
            )


if __name__ == "__main__":
    main()
