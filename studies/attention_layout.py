"""Frame-local attention against full attention at equal compute (issue 19: a DiT ahead of its peers).

``DiTConfig.full_attn_every = k`` makes every k-th block attend across the whole clip and the others
within their own latent frame: the same parameters, 1/t of the attention FLOPs in the frame-local
blocks. This study trains the same Text2World network with each layout through the shared loop
(``drivewm pretrain``'s :func:`pretrain`) at equal CPU time and compares held-out quality:

1. cost: one training step of every layout on the cache's latent shape, interleaved rounds, the
   median of the process's CPU seconds (as ``benchmarks/bench_dit.py`` times steps);
2. training: layout 1 (full attention) runs ``--steps``; layout k runs ``--steps`` x its cost ratio,
   so every layout spends the same compute (the CPU seconds each really spent are printed beside);
3. quality: the held-out x0 error per latent element at a fixed sigma grid and its mean
   (``tests/diffusion/study_flow_vs_edm.py``'s measure: the same noised inputs for every model).

    python studies/attention_layout.py --data CLIPDIR/latents/tokenizer --out /tmp/attn --steps 240 \\
        --layouts 1 3 --set model.depth=6 --set train.batch_size=4

Results are printed and written to OUT/results.json, with a plot of the x0 error against sigma at
OUT/x0_error.png (``--plot-only`` redraws it from an existing results.json).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
import time
from pathlib import Path

import matplotlib
import torch

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO / "tests" / "diffusion"), str(REPO / "benchmarks")]  # the flow study's and bench_dit's helpers
from bench_dit import timed_step  # noqa: E402
from study_flow_vs_edm import SIGMAS, split_cache, x0_errors  # noqa: E402

from drivewm.atomic import write_text  # noqa: E402
from drivewm.diffusion.data import LatentDataset  # noqa: E402
from drivewm.diffusion.denoiser import Conditioning, EDMDenoiser, edm_loss  # noqa: E402
from drivewm.diffusion.dit import DiT, count_parameters  # noqa: E402
from drivewm.diffusion.pretrain import PretrainConfig, pretrain, pretrain_config  # noqa: E402
from drivewm.diffusion.text2world import Text2World  # noqa: E402


def layout_config(args: argparse.Namespace, k: int, steps: int | None = None) -> PretrainConfig:
    overrides = [*args.overrides, f"model.full_attn_every={k}"]
    return pretrain_config(args.preset, overrides + ([f"train.steps={steps}"] if steps else []))


def step_cpu_seconds(cfgs: dict[int, PretrainConfig], shape: tuple[int, ...], rounds: int) -> dict[int, float]:
    """Median CPU seconds of one training step (forward, EDM loss, backward, AdamW) of each layout on
    batches of latents ``shape`` (c, t, h, w), the layouts interleaved round by round."""
    torch.manual_seed(0)
    runs = {}
    for k, cfg in cfgs.items():
        model = EDMDenoiser(DiT(dataclasses.replace(cfg.model, in_channels=shape[0])), cfg.edm)
        b = cfg.train.batch_size
        x0, noise = torch.randn(b, *shape), torch.randn(b, *shape)
        cond = Conditioning(
            torch.randn(b, 32, cfg.model.text_dim), torch.ones(b, 32, dtype=torch.bool), torch.full((b,), 10.0)
        )
        sigma, keep = torch.ones(b), torch.ones(b, dtype=torch.bool)
        opt = torch.optim.AdamW(model.parameters(), lr=1e-4, fused=True)  # as bench_dit times every model
        runs[k] = (
            model,
            opt,
            lambda m=model, x0=x0, c=cond, s=sigma, n=noise, kp=keep: edm_loss(m, m.cfg, x0, c, s, n, kp),
        )
    times = {k: [] for k in runs}
    for r in range(rounds + 1):  # round 0 warms up
        for k, (model, opt, loss_fn) in runs.items():
            dt = timed_step(model, loss_fn, opt, False, torch.device("cpu"))  # CPU seconds of the process
            if r:
                times[k].append(dt)
    print("parameters:", {k: count_parameters(m) for k, (m, _, _) in runs.items()})
    return {k: statistics.median(t) for k, t in times.items()}


def run(args: argparse.Namespace) -> dict:
    out = Path(args.out)
    if not args.data:
        raise SystemExit("--data is required to train (only --plot-only works without it)")
    train_dir, held_dir = split_cache(Path(args.data), out / "split", args.held_every)
    base = layout_config(args, 1)
    shape = tuple(LatentDataset(train_dir, base.edm.sigma_data)[0].latents.shape)
    cost = step_cpu_seconds({k: layout_config(args, k) for k in args.layouts}, shape, args.cost_rounds)
    results = {"steps_full": args.steps, "preset": args.preset, "overrides": args.overrides, "sigmas": SIGMAS}
    results["latent_shape"], results["step_cpu_s"] = list(shape), cost
    for k in args.layouts:
        steps = round(args.steps * cost[1] / cost[k])
        tic = time.process_time()
        pretrain(layout_config(args, k, steps), train_dir, None, out / f"every{k}")
        model = Text2World.from_pretrained(out / f"every{k}")
        held = LatentDataset(held_dir, model.cfg.edm.sigma_data)
        errors = x0_errors(model, held)
        results[f"every{k}"] = {
            "steps": steps,
            "train_cpu_s": round(time.process_time() - tic, 1),
            "x0_error_by_sigma": errors,
            "x0_error_mean": sum(errors) / len(errors),
        }
        write_text(out / "results.json", json.dumps(results, indent=2) + "\n")
    return results


def report(results: dict, layouts: list[int]) -> None:
    names = [f"every{k}" for k in layouts]
    print(f"latents {results['latent_shape']}; step CPU s {results['step_cpu_s']}")
    print(f"{'sigma':>8s} " + " ".join(f"{n:>10s}" for n in names))
    for i, sigma in enumerate(results["sigmas"]):
        print(f"{sigma:8.2f} " + " ".join(f"{results[n]['x0_error_by_sigma'][i]:10.4f}" for n in names))
    for key in ("x0_error_mean", "steps", "train_cpu_s"):
        print(f"{key:>14s} " + " ".join(f"{results[n][key]:10.4f}" for n in names))


def plot(results: dict, layouts: list[int], path: Path) -> None:
    """x0 error against sigma (log-log), one line per layout, steps and CPU seconds in the legend."""
    fig, ax = plt.subplots(figsize=(6, 4), dpi=120)
    for k in layouts:
        r = results[f"every{k}"]
        name = "full attention" if k == 1 else f"full every {k}, frame-local between"
        label = f"{name}: {r['steps']} steps, {r['train_cpu_s']:.0f} CPU s, mean {r['x0_error_mean']:.4f}"
        ax.loglog(results["sigmas"], r["x0_error_by_sigma"], marker="o", label=label)
    c, t, h, w = results["latent_shape"]
    ax.set(xlabel="sigma", ylabel="held-out x0 error (per latent element)")
    ax.set_title(f"equal compute, {t} x {h // 2} x {w // 2} tokens per clip", fontsize=10)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", help="latent cache folder (CLIPDIR/latents/TOKENIZER); needed unless --plot-only")
    parser.add_argument("--out", default="/tmp/attention_layout", help="run folder (models, split caches, results)")
    parser.add_argument("--preset", default="debug")
    parser.add_argument("--layouts", type=int, nargs="+", default=[1, 3], help="full_attn_every values; 1 first")
    parser.add_argument("--steps", type=int, default=240, help="training steps of the full-attention model")
    parser.add_argument("--held-every", type=int, default=6, help="every n-th clip is held out")
    parser.add_argument("--cost-rounds", type=int, default=3, help="timed steps per layout for the cost ratio")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--plot-only", action="store_true", help="redraw OUT/x0_error.png from OUT/results.json")
    args = parser.parse_args(argv)
    if args.layouts[0] != 1:
        parser.error("--layouts must start with 1 (full attention: the reference of equal compute)")
    torch.set_num_threads(1)
    out = Path(args.out)
    results = json.loads((out / "results.json").read_text()) if args.plot_only else run(args)
    report(results, args.layouts)
    plot(results, args.layouts, out / "x0_error.png")


if __name__ == "__main__":
    sys.exit(main())
