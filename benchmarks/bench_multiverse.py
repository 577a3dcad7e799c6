"""Time of ``drivewm multiverse``: five 8-second futures of a nuscenes6 drive at 320x192, scoring included.

The must-hold limit: at most 10 minutes on 2 cores. The cameras are the simulator's renderer
(``--renderer sim``), or, with ``--model DIR`` (``shipped:multiview``: the shipped multi-view model), a
multi-view world model generating each future (``--renderer model``, ``--steps`` sampler steps per
window; drivewm.multiverse.model_cameras); ``--renderer both`` times the two interleaved, so the model's
share is the difference. The model's parameter counts (network, tokenizer) are printed with the times.

Two sources, interleaved ``--repeats`` times (medians): a recorded nuscenes6 drive (simulated once, then
branched as a log: road users replayed) and the same scenario forked in highway-env (reactive). Each run
can also run without ``drivewm eval`` (``--no-eval-runs``) to split the video scores' cost off. Prints wall and CPU
seconds, the torch threads (``--threads``, default every core: the model's network uses both of 2; OpenMP's
wait policy passive) and the ratio of the wall time to the 600 s limit.

    python benchmarks/bench_multiverse.py                          # 8 s horizon, 1 repeat, both sources
    python benchmarks/bench_multiverse.py --horizon 2 --no-eval-runs  # a quick look, eval's share split off
    python benchmarks/bench_multiverse.py --sources log --renderer model --model shipped:multiview  # 10 steps
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")
# Idle OpenMP threads sleep rather than spin: on a shared 2-core machine spinning threads took 2.3x the
# wall time of one thread (load 6); sleeping ones 0.8x. Read when torch loads OpenMP, so set before it.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import torch  # noqa: E402

from drivewm.multiverse import MultiverseConfig, run_multiverse  # noqa: E402
from drivewm.sim import SimConfig, simulate  # noqa: E402

LIMIT_S = 600.0
PLANS = ["keep", "left", "right", "brake", "accelerate"]


def timed(cfg: MultiverseConfig, out: Path) -> tuple[float, float]:
    """(wall s, CPU s of this process) of one run into a fresh folder."""
    shutil.rmtree(out, ignore_errors=True)
    w0, c0 = time.perf_counter(), time.process_time()
    run_multiverse(cfg, out, progress=False)
    return time.perf_counter() - w0, time.process_time() - c0


def with_renderers(runs: dict[str, MultiverseConfig], args: argparse.Namespace) -> dict[str, MultiverseConfig]:
    """Each run with the renderers ``args.renderer`` asks for, named ``SOURCE, RENDERER``."""
    model = dict(renderer="model", model=args.model, model_steps=args.steps)
    renderers = {"sim": {}, "model": model}
    chosen = ["sim", "model"] if args.renderer == "both" else [args.renderer]
    return {f"{k}, {r}": dataclasses.replace(v, **renderers[r]) for k, v in runs.items() for r in chosen}


def model_parameters(folder: str) -> dict[str, int]:
    """Parameter counts of the model renderer's network and tokenizer."""
    from drivewm.model_folders import resolve_model_folder
    from drivewm.multiverse.model_cameras import load_world_model

    gen = load_world_model(resolve_model_folder(folder), "cpu")
    count = lambda module: sum(p.numel() for p in module.parameters())  # noqa: E731
    return {"network": count(gen.model.net), "tokenizer": count(gen.tokenizer)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--horizon", type=float, default=8.0)
    p.add_argument("--repeats", type=int, default=1)
    p.add_argument("--at", type=float, default=2.0)
    p.add_argument("--sources", default="log,highway-env", help="which of log, highway-env to time")
    p.add_argument("--no-eval-runs", action="store_true", help="also time each source without drivewm eval")
    p.add_argument("--model", default="", help="multi-view model folder (or shipped:multiview) of --renderer model")
    p.add_argument("--steps", type=int, default=MultiverseConfig.model_steps, help="sampler steps a model window")
    p.add_argument("--renderer", default="sim", choices=["sim", "model", "both"], help="cameras to time")
    p.add_argument("--threads", type=int, default=os.cpu_count(), help="torch threads (default: every core)")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    if args.renderer != "sim" and not args.model:
        p.error("--renderer model/both needs --model DIR")
    with tempfile.TemporaryDirectory(prefix="bench-multiverse-") as tmp:
        tmp = Path(tmp)
        drive = SimConfig(source="highway", scenario="highway", rig="nuscenes6", width=320, height=192, seed=7)
        drive.duration_s = args.at + args.horizon + 0.5
        log = simulate(drive, tmp / "drive.mcap", progress=False)
        common = dict(at_s=args.at, horizon_s=args.horizon, plans=PLANS, width=320, height=192, seed=7)
        runs = {
            "log": MultiverseConfig(log=str(log), **common),
            "highway-env": MultiverseConfig(scenario="highway", **common),
        }
        runs = {k: v for k, v in runs.items() if k in args.sources.split(",")}
        runs = with_renderers(runs, args)
        if args.no_eval_runs:
            runs |= {f"{k} (no eval)": dataclasses.replace(v, eval_metrics=[]) for k, v in list(runs.items())}
        times: dict[str, list[tuple[float, float]]] = {k: [] for k in runs}
        for _ in range(args.repeats):  # interleaved: the machine's load falls on every variant alike
            for name, cfg in runs.items():
                times[name].append(timed(cfg, tmp / "out"))
    print(f"five {args.horizon:g} s futures, nuscenes6 at 320x192, {args.repeats} repeat(s), medians:")
    print(f"  torch threads {torch.get_num_threads()} of {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
    if args.renderer != "sim":
        params = ", ".join(f"{k} {v / 1e6:.2f}M" for k, v in model_parameters(args.model).items())
        print(f"  model {args.model}: {params} parameters, {args.steps} sampler steps per window")
    for name, ts in times.items():
        wall, cpu = statistics.median(t[0] for t in ts), statistics.median(t[1] for t in ts)
        print(f"  {name:34s} wall {wall:7.1f} s  cpu {cpu:7.1f} s  wall / limit {wall / LIMIT_S:.2f}")


if __name__ == "__main__":
    main()
