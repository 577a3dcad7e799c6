"""Flow matching against EDM at equal compute on a latent cache (issue 12, item 1).

The same Text2World network is trained twice by the shared loop, ``edm.parameterization=edm`` and
``edm.parameterization=flow`` (each with its own default noise distribution: EDM's log-normal
sigma, SD3's logit-normal t), with the same preset, steps, batch, learning rate, seed and clips.
Both are then scored on held-out clips with quantities that mean the same for both: each model is
an EDM-form denoiser D(x; sigma), so the same noised inputs x = x0 + sigma n go to both.

- x0 error: E ||D(x0 + sigma n; sigma) - x0||^2 per latent element (normalised latents, caption
  given) at a fixed grid of sigmas, and its mean over the grid;
- samples: one clip per held-out caption and seed (Heun, fixed seeds), per-channel mean and std of
  the generated latents against the held-out latents': the mean gap over channels and the mean
  ratio of stds (1 = the data's spread).

    python tests/diffusion/study_flow_vs_edm.py                        # synthetic cache, debug DiT, 300 steps
    python tests/diffusion/study_flow_vs_edm.py --data CLIPDIR/latents/TOK --steps 4000 --out runs/fve \\
        --set model.hidden_dim=256 --set model.depth=8 --set train.batch_size=16

Results are printed and written to OUT/results.json;
``--plot OUT.png RUN1/results.json RUN2/results.json ...`` draws finished runs side by side.

``--pixels MODEL...`` scores trained models in pixels instead, on the split's held-out clips (front
view, its caption, seed = clip index, Heun): each sample decoded by the tokenizer that encoded the
cache and set beside the same tokenizer's decoding of the real clip, scored by the eval's condition
classifier (drivewm.eval.adherence, its ``coded`` domain): weather and time-of-day adherence to the
clip's tags, the real clips' own as the ceiling; the condition features' distance between samples
and real clips (z-scored as the classifier scores them, class means per weather x time of day,
averaged over classes); and texture, mean |Laplacian| (``edge_energy``) over the real clips'.

    python tests/diffusion/study_flow_vs_edm.py --out RUN --pixels RUN/edm RUN/flow [--max-clips 120]
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

import torch

from drivewm.atomic import write_text
from drivewm.clips.latents import write_latent_index
from drivewm.diffusion.data import LatentDataset, normalize_latents
from drivewm.diffusion.pretrain import pretrain, pretrain_config
from drivewm.diffusion.text2world import Text2World

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from synthetic_latents import make_synthetic_latent_cache  # noqa: E402

#: The sigma grid of the x0 error (VE noise levels; t = sigma / (1 + sigma) for the flow model).
SIGMAS = [0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0]
PARAMETERIZATIONS = ("edm", "flow")


def split_cache(cache: Path, out: Path, held_every: int) -> tuple[Path, Path]:
    """(train, held-out) latent caches of ``cache``'s clips: every ``held_every``-th clip is held out."""
    index = json.loads((cache / "index.json").read_text())
    rows = index["clips"]
    parts = {"train": [r for i, r in enumerate(rows) if i % held_every], "held": rows[::held_every]}
    for name, part in parts.items():
        (out / name).mkdir(parents=True, exist_ok=True)
        for row in part:
            shutil.copy2(cache / row["file"], out / name / row["file"])
        write_latent_index(out / name, index["tokenizer"], part)
    return out / "train", out / "held"


@torch.no_grad()
def x0_errors(model: Text2World, held: LatentDataset, seed: int = 1000) -> list[float]:
    """Mean squared x0 error per latent element at each sigma of :data:`SIGMAS` (held-out samples)."""
    samples = [held[i] for i in range(len(held))]
    x0 = torch.stack([s.latents for s in samples])  # (M, c, t, h, w) normalised
    cond = model.conditioning([s.caption for s in samples], held.fps)
    g = torch.Generator().manual_seed(seed)
    errors = []
    for sigma in SIGMAS:
        noise = torch.randn(x0.shape, generator=g)
        s = torch.full((len(x0),), sigma)
        errors.append(float(((model.denoiser(x0 + sigma * noise, s, cond) - x0) ** 2).mean()))
    return errors


def sample_statistics(model: Text2World, held: LatentDataset, steps: int, guidance: float) -> dict:
    """Per-channel mean gap and std ratio of generated latents (one per held-out sample) against the held-out's."""
    samples = [held[i] for i in range(len(held))]
    raw = model.sample_latents([s.caption for s in samples], list(range(len(samples))), steps, guidance)
    mean, std = held.cache.latent_mean, held.cache.latent_std
    gen = normalize_latents(raw, mean, std, held.sigma_data).transpose(0, 1).flatten(1)  # (c, M*t*h*w)
    data = torch.stack([s.latents for s in samples]).transpose(0, 1).flatten(1)
    return {
        "channel_mean_gap": float((gen.mean(1) - data.mean(1)).abs().mean()),
        "channel_std_ratio": float((gen.std(1) / data.std(1)).mean()),
    }


def run(args: argparse.Namespace) -> dict:
    out = Path(args.out)
    cache = Path(args.data) if args.data else make_synthetic_latent_cache(out / "synthetic", clips_per_condition=12)
    train_dir, held_dir = split_cache(cache, out / "split", args.held_every)
    results = {"steps": args.steps, "preset": args.preset, "overrides": args.overrides, "sigmas": SIGMAS}
    for p in args.parameterizations.split(","):
        overrides = [f"train.steps={args.steps}", *args.overrides, f"edm.parameterization={p}"]
        cfg = pretrain_config(args.preset, overrides)
        tic = time.perf_counter()
        pretrain(cfg, train_dir, None, out / p)
        train_s = time.perf_counter() - tic
        model = Text2World.from_pretrained(out / p)
        held = LatentDataset(held_dir, model.cfg.edm.sigma_data)
        errors = x0_errors(model, held)
        results[p] = {
            "train_s": round(train_s, 1),
            "x0_error_by_sigma": errors,
            "x0_error_mean": sum(errors) / len(errors),
            **sample_statistics(model, held, args.sample_steps, args.guidance),
        }
    write_text(out / "results.json", json.dumps(results, indent=2) + "\n")
    return results


def pixel_scores(model_dirs: list[str], held_dir: Path, steps: int, guidance: float, max_clips: int) -> dict:
    """The ``--pixels`` figures of each model folder, and of the real clips coded by the tokenizer."""
    import numpy as np

    from drivewm.clips.latents import LatentCache
    from drivewm.diffusion.generate import decode_latents
    from drivewm.eval.adherence import adherence, condition_scores, load_calibration

    cache = LatentCache(held_dir)
    tokenizer = cache.tokenizer["path"]
    picks = np.unique(np.linspace(0, len(cache) - 1, min(max_clips, len(cache))).round().astype(int))
    clips = [cache[int(i)] for i in picks]
    captions = [c.meta.view_captions.get(c.meta.cameras[0]) or c.meta.caption for c in clips]
    tags = [c.meta.tags for c in clips]
    calibration = load_calibration()
    mean, std = np.asarray(calibration["mean"]), np.asarray(calibration["std"])

    def score(latents: torch.Tensor) -> dict:
        video = decode_latents(latents, tokenizer)  # (N, T, H, W, 3)
        feats = [condition_scores(v[None]) for v in video]
        adh = [adherence(f, t) for f, t in zip(feats, tags)]
        z = np.array([[f[k] for k in calibration["features"]] for f in feats])
        return {
            "weather": float(np.mean([a["weather_match"] for a in adh])),
            "time_of_day": float(np.mean([a["time_of_day_match"] for a in adh])),
            "z": (z - mean) / std,
            "edge_energy": float(np.mean([f["edge_energy"] for f in feats])),
        }

    classes = [f"{t['weather']}/{t['time_of_day']}" for t in tags]
    real = score(torch.stack([c.latents[0, :, :1] for c in clips]))
    out = {"clips": len(clips), "tokenizer": tokenizer, "real": {k: v for k, v in real.items() if k != "z"}}
    for folder in model_dirs:
        model = Text2World.from_pretrained(folder)
        seeds = [int(i) for i in picks]
        gen = score(
            torch.cat(
                [
                    model.sample_latents(captions[a : a + 16], seeds[a : a + 16], steps, guidance)
                    for a in range(0, len(clips), 16)
                ]
            )
        )
        gaps = [
            float(np.linalg.norm(gen["z"][m].mean(0) - real["z"][m].mean(0)))
            for c in sorted(set(classes))
            for m in [np.array([k == c for k in classes])]
        ]
        out[str(folder)] = {
            "parameterization": model.cfg.edm.parameterization,
            "weather": gen["weather"],
            "time_of_day": gen["time_of_day"],
            "feature_gap": float(np.mean(gaps)),
            "edge_energy_ratio": gen["edge_energy"] / real["edge_energy"],
        }
    return out


def report(results: dict) -> None:
    print(f"{'sigma':>8s} " + " ".join(f"{p:>10s}" for p in PARAMETERIZATIONS))
    for i, sigma in enumerate(results["sigmas"]):
        row = [f"{results[p]['x0_error_by_sigma'][i]:10.4f}" for p in PARAMETERIZATIONS if p in results]
        print(f"{sigma:8.2f} " + " ".join(row))
    for key in ("x0_error_mean", "channel_mean_gap", "channel_std_ratio", "train_s"):
        print(f"{key:>18s} " + " ".join(f"{results[p][key]:10.4f}" for p in PARAMETERIZATIONS if p in results))


def plot(result_files: list[str], out: str) -> None:
    """x0 error against sigma of every parameterization in every results.json given (one line per
    run, labelled by parameterization and seed), and each one's error relative to the first EDM run's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = []
    for f in result_files:
        res = json.loads(Path(f).read_text())
        seed = next((o.split("=", 1)[1] for o in res["overrides"] if o.startswith("train.seed=")), "0")
        runs += [
            (f"{p}, seed {seed}", res["sigmas"], res[p]["x0_error_by_sigma"]) for p in PARAMETERIZATIONS if p in res
        ]
    base = next(errors for label, _, errors in runs if label.startswith("edm"))
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for label, sigmas, errors in runs:
        style = "-" if label.startswith("edm") else "--"
        axes[0].plot(sigmas, errors, style, marker="o", ms=3, label=label)
        axes[1].plot(sigmas, [e / b for e, b in zip(errors, base)], style, marker="o", ms=3, label=label)
    axes[0].set(xscale="log", yscale="log", xlabel="sigma", ylabel="x0 error (held-out, per element)")
    axes[1].set(xscale="log", xlabel="sigma", ylabel=f"relative to {runs[0][0]}")
    axes[1].axhline(1.0, color="grey", lw=0.8)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(out)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", help="latent cache folder (default: a synthetic one)")
    parser.add_argument("--out", default="/tmp/flow_vs_edm", help="run folder (models, split caches, results.json)")
    parser.add_argument("--preset", default="debug")
    parser.add_argument("--steps", type=int, default=300, help="training steps of each model")
    parser.add_argument("--held-every", type=int, default=4, help="every n-th clip is held out")
    parser.add_argument("--sample-steps", type=int, default=20)
    parser.add_argument("--guidance", type=float, default=1.0, help="caption guidance of the samples")
    parser.add_argument(
        "--parameterizations",
        default=",".join(PARAMETERIZATIONS),
        help="which to train (default both; one per process runs them on two cores at once, same split)",
    )
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument(
        "--plot", nargs="+", metavar="FILE", help="PNG RESULTS.json...: plot finished runs, train nothing"
    )
    parser.add_argument("--pixels", nargs="+", metavar="MODEL", help="score these trained models in pixels")
    parser.add_argument("--max-clips", type=int, default=120, help="held-out clips --pixels samples")
    args = parser.parse_args(argv)
    if args.plot:
        return plot(args.plot[1:], args.plot[0])
    if args.pixels:
        torch.set_num_threads(2)
        result = pixel_scores(
            args.pixels, Path(args.out) / "split" / "held", args.sample_steps, args.guidance, args.max_clips
        )
        write_text(Path(args.out) / "pixels.json", json.dumps(result, indent=2) + "\n")
        return print(json.dumps(result, indent=2))
    torch.set_num_threads(1)
    report(run(args))


if __name__ == "__main__":
    sys.exit(main())
