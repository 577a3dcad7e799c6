"""Diffusion against autoregressive world models at equal training compute, on the same held-out clips.

Both families train from scratch on one FSQ tokenizer's latent cache (``drivewm tokenizer encode`` of
``--data``) by the shared loop, each for the same **process CPU-seconds** (``time.process_time`` of
the training calls: steps, setup and checkpoints alike; one torch thread):

- ``ar``: drivewm.ar at ``--ar-preset`` (next-token prediction on the FSQ indices);
- ``diffusion``: the multi-view, trajectory-conditioned DiT (drivewm.multiview posttraining with
  Video2World) at ``--dit-preset``, started from an untrained Text2World folder (no pretraining
  compute), on the same cache's codes as continuous latents.

Training runs in calls of a few steps; after each the CPU spent is read, and at every point of
``--cpu-seconds`` the model folder is scored. Both are scored through the one generation path
(drivewm.generate.registry: ``rollout`` of each folder's generator) on the clips of ``--heldout``
(drives neither saw):

- Video2World: one window from each clip's first frame under its own logged trajectory; PSNR of the
  first generated frame and of the whole window against the truth, beside copying the given frame and
  the tokenizer's own reconstruction (the ceiling of both);
- consistency on those windows: the eval suite's TSE and CSE (fitted F, px) and verified matches;
- turn sign: straight held-out clips continued under ``left`` and ``right``, the yaw read by the
  eval's dense-flow reader (drivewm.eval.trajectory.flow_fallback) from the front camera;
- rollouts: ``--rollout-windows`` chunks under ``straight``; TSE matches per frame pair and image
  sharpness per chunk (the first against the last);
- sampling CPU-seconds and wall seconds per window;
- AR only, when ``--heldout`` holds the tokenizer's cache: held-out bits per token against the copy and
  unigram baselines (drivewm.ar.evaluate).

Every point gets the Video2World figures (the curve); the last point gets all. Parameter counts are
printed beside. Results: OUT/FAMILY/results.json; the table of every family found in OUT is
printed at the end (run ``--family ar`` and ``--family diffusion`` in two processes to use two cores). A
rerun with the same ``--out`` and more points goes on from the last one scored.

    python benchmarks/bench_ar_vs_diffusion.py --data CLIPS --heldout HELDOUT --tokenizer FSQDIR \\
        --out RUN --cpu-seconds 100,200,400,800 --figure ar_vs_diffusion.png
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from pathlib import Path

import numpy as np
import torch

from drivewm.clips.latents import find_latent_cache
from drivewm.clips.shards import iter_clips
from drivewm.eval.config import EvalConfig
from drivewm.eval.consistency import cross_sampson, overlapping_pairs, temporal_sampson
from drivewm.eval.matching import FrameMatcher
from drivewm.eval.trajectory import flow_fallback
from drivewm.eval.trajectory_errors import heading_change_deg
from drivewm.generate.config import RECIPES as GENERATE
from drivewm.generate.registry import load_generator
from drivewm.multiview.trajectories import waypoints_from_poses

STRAIGHT_DEG = 5.0
FAMILIES = ("ar", "diffusion")


@dataclasses.dataclass
class Budget:
    """Where a family's training stands."""

    cpu_s: float = 0.0
    """Process CPU-seconds spent in training calls so far."""
    steps: int = 0
    """Optimizer steps so far."""
    calls: int = 0
    """Training calls so far (each one pays its setup and a checkpoint)."""


def run_steps(family: str, args: argparse.Namespace, out: Path, steps: int) -> None:
    """``steps`` more optimizer steps of ``family`` in ``out`` (created or resumed)."""
    common = ["train.steps=100000000", "train.checkpoint_every=100000000", "train.device=cpu", "train.log_every=5"]
    if family == "ar":
        from drivewm.ar.train import RECIPES, ar_train

        cfg = RECIPES.resolve(args.ar_preset, None, common + ["data.holdout_percent=0"])
        ar_train(cfg, args.data, args.tokenizer, out, stop_after=steps)
    else:
        from drivewm.multiview.posttrain import posttrain, posttrain_config

        cfg = posttrain_config(args.dit_preset, common + ["trajectory_probe_every=0"])
        posttrain(cfg, untrained_text2world(args), args.data, out, stop_after=steps)


def untrained_text2world(args: argparse.Namespace) -> Path:
    """A Text2World folder at ``--dit-preset`` with its initial weights, shaped for the cache (the
    multi-view model's starting point; no training compute)."""
    from drivewm.diffusion.data import LatentDataset
    from drivewm.diffusion.pretrain import latent_info, pretrain_config, resolve_for_data
    from drivewm.diffusion.text2world import Text2World, Text2WorldConfig

    folder = args.out / "diffusion_init"
    if not (folder / "config.json").exists():
        cfg = pretrain_config(args.dit_preset)
        dataset = LatentDataset(find_latent_cache(args.data, args.tokenizer, None), cfg.edm.sigma_data)
        cfg = resolve_for_data(cfg, dataset)
        torch.manual_seed(0)
        bundle = Text2World(Text2WorldConfig(cfg.model, cfg.edm, cfg.text), latent_info(dataset, args.tokenizer))
        bundle.save_pretrained(folder)
    return folder


def train_to(family: str, args: argparse.Namespace, out: Path, budget: Budget, target_cpu_s: float) -> None:
    """Train until ``budget.cpu_s`` reaches ``target_cpu_s`` (within one call's last step), planning each
    call's steps from the CPU per step of the calls so far."""
    while budget.cpu_s < target_cpu_s:
        per_step = budget.cpu_s / budget.steps if budget.steps else None
        steps = 10 if per_step is None else max(1, int((target_cpu_s - budget.cpu_s) / per_step))
        tic = time.process_time()
        run_steps(family, args, out, steps)
        budget.cpu_s += time.process_time() - tic
        budget.steps += steps
        budget.calls += 1
        print(f"{family}: {budget.steps} steps, {budget.cpu_s:.0f} CPU-s", flush=True)


def parameter_count(folder: Path) -> int:
    """Parameters in the model folder's weights (the same count for every family)."""
    from safetensors import safe_open

    with safe_open(str(folder / "model.safetensors"), "pt") as f:
        return sum(math.prod(f.get_slice(k).get_shape()) for k in f.keys())


def heldout_clips(folder: Path, count: int, straight: bool = False) -> list:
    """The first ``count`` clips of each drive in turn (round robin over shards), straight ones only if
    asked (logged heading change under STRAIGHT_DEG)."""

    def keep(clip) -> bool:
        return not straight or abs(heading_change_deg(clip.T_world_from_ego)) < STRAIGHT_DEG

    per_shard = [[c for c in iter_clips(shard) if keep(c)] for shard in sorted(folder.glob("*.tar"))]
    out = [s[i] for i in range(max(map(len, per_shard), default=0)) for s in per_shard if i < len(s)]
    return out[:count]


def truth_video(clip, names: list[str]) -> np.ndarray:
    """uint8 (V, T, H, W, 3) of the clip's cameras ``names``."""
    return np.stack([clip.video(n) for n in names])


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR (dB) of uint8 arrays."""
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return 10 * math.log10(255**2 / max(mse, 1e-10))


def sharpness(video: np.ndarray) -> float:
    """Mean absolute difference of horizontally adjacent luma pixels (texture a drifting rollout loses)."""
    luma = video.astype(np.float64).mean(-1)
    return float(np.abs(np.diff(luma, axis=-1)).mean())


class Scorer:
    """Rollouts of one model folder through its generator, timed."""

    def __init__(self, folder: Path, args: argparse.Namespace):
        self.gen = load_generator(folder, "cpu")
        self.trajectories = args.out / f"trajectories-{folder.name}"  # each family's process writes its own
        self.args = args
        self.seconds: list[tuple[float, float]] = []  # (CPU-s, wall-s) per window

    def rollout(self, clip, trajectory: str, windows: int, seed: int):
        settings = [f"trajectory={trajectory}", f"rollout.windows={windows}", f"sampling.seed={seed}"]
        settings += [f"sampling.steps={self.args.steps}", f"sampling.guidance={self.args.guidance}"]
        settings += [f"tokens.top_k={self.args.top_k}"]
        cpu, wall = time.process_time(), time.perf_counter()
        sample = self.gen.rollout(clip, GENERATE.resolve(overrides=settings))
        self.seconds.append(((time.process_time() - cpu) / windows, (time.perf_counter() - wall) / windows))
        return sample


def own_trajectory(clip, folder: Path) -> str:
    """A waypoint file of the clip's logged ego path (extrapolated past its end), for ``trajectory=``."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{clip.key.replace('/', '_')}.npy"
    np.save(path, waypoints_from_poses(clip.T_world_from_ego, 0, 4 * clip.meta.num_frames))
    return str(path)


def consistency(videos: np.ndarray, rig) -> dict:
    """The eval suite's TSE and CSE (fitted F, px) and TSE verified matches per frame pair."""
    cfg = EvalConfig()
    named = {n: videos[i] for i, n in enumerate(rig.names)}
    matcher = FrameMatcher(cfg.match)
    tse = temporal_sampson(named, rig, None, cfg.epipolar, cfg.consistency, matcher)["fitted"]
    pairs = overlapping_pairs(rig, cfg.consistency)
    cse = cross_sampson(named, rig, pairs, cfg.epipolar, matcher, cfg=cfg.consistency)["fitted"] if pairs else {}
    return {
        "tse_px": tse["value_px"],
        "tse_matches": tse["matches_per_pair"],
        "tse_counted": tse["counted_fraction"],
        "cse_px": cse.get("value_px", math.nan),
    }


@torch.no_grad()
def reconstruction(tokenizer, truth: np.ndarray) -> np.ndarray:
    """uint8 (V, T, H, W, 3) of ``truth`` encoded and decoded by the tokenizer: the best either family's
    decoded frames can be."""
    from drivewm.tokenizer.data import to_model_range, to_uint8

    video = torch.stack([to_model_range(v) for v in truth])  # (V, 3, T, H, W)
    decoded = tokenizer.decode(tokenizer.encode(video)).clamp(-1, 1)
    return np.stack([to_uint8(v) for v in decoded])


def video2world(scorer: Scorer, clips: list, args: argparse.Namespace, with_consistency: bool) -> dict:
    """First generated frame and whole-window PSNR against the truth under the logged trajectory, beside
    copying the given frame and the tokenizer's own reconstruction."""
    from drivewm.tokenizer import Tokenizer

    tokenizer, rows = Tokenizer.from_pretrained(args.tokenizer), []
    for i, clip in enumerate(clips):
        sample = scorer.rollout(clip, own_trajectory(clip, scorer.trajectories), 1, args.seed + i)
        gen, truth = sample.videos, truth_video(clip, sample.rig.names)
        n = min(gen.shape[1], truth.shape[1])
        row = {
            "first": psnr(gen[:, 1], truth[:, 1]),
            "copy_first": psnr(truth[:, 0], truth[:, 1]),
            "window": psnr(gen[:, 1:n], truth[:, 1:n]),
            "copy_window": psnr(np.repeat(truth[:, :1], n - 1, 1), truth[:, 1:n]),
            "tokenizer_window": psnr(reconstruction(tokenizer, truth[:, :n])[:, 1:], truth[:, 1:n]),
        }
        if with_consistency:
            row.update(consistency(gen[:, 1:n], sample.rig))
            row.update({f"truth_{k}": v for k, v in consistency(truth[:, 1:n], sample.rig).items()})
        rows.append(row)
    out = {k: float(np.nanmean([r[k] for r in rows])) for k in rows[0]}
    out["first_closer"] = sum(r["first"] > r["copy_first"] for r in rows)
    out["clips"] = len(rows)
    return out


def turn_sign(scorer: Scorer, clips: list, args: argparse.Namespace) -> dict:
    """Turn sign over straight clips continued under left and right (an unread yaw counts as wrong)."""
    yaws = {"left": [], "right": []}
    for i, clip in enumerate(clips):
        for turn in yaws:
            sample = scorer.rollout(clip, turn, 1, args.seed + i)
            named = {n: sample.videos[j] for j, n in enumerate(sample.rig.names)}
            ego = flow_fallback(named, sample.rig)
            registered = ego.T_world_from_ego[ego.registered]
            yaws[turn].append(heading_change_deg(registered) if len(registered) >= 2 else math.nan)
    left, right = np.array(yaws["left"]), np.array(yaws["right"])
    right_sign = int(np.sum(left > 0) + np.sum(right < 0))
    return {
        "turn_sign": right_sign / (len(left) + len(right)),
        "samples": len(left) + len(right),
        "mean_yaw_left_deg": float(np.nanmean(left)),
        "mean_yaw_right_deg": float(np.nanmean(right)),
    }


def rollouts(scorer: Scorer, clips: list, args: argparse.Namespace) -> dict:
    """Per chunk (16 new frames each): TSE verified matches per frame pair and sharpness, over clips."""
    per_chunk = [[] for _ in range(args.rollout_windows)]
    for i, clip in enumerate(clips):
        sample = scorer.rollout(clip, "straight", args.rollout_windows, args.seed + i)
        step = (sample.videos.shape[1] - 1) // args.rollout_windows
        for k in range(args.rollout_windows):
            chunk = sample.videos[:, k * step : (k + 1) * step + 1]
            c = consistency(chunk, sample.rig)
            per_chunk[k].append((c["tse_matches"], sharpness(chunk)))
    matches = [float(np.mean([m for m, _ in rows])) for rows in per_chunk]
    sharp = [float(np.mean([s for _, s in rows])) for rows in per_chunk]
    return {"matches_per_pair": matches, "sharpness": sharp, "kept": matches[-1] / max(matches[0], 1e-9)}


def ar_bits(folder: Path, args: argparse.Namespace) -> dict:
    """The AR model's held-out bits per token against the copy and unigram baselines (drivewm.ar.evaluate)."""
    from drivewm.ar.evaluate import bits_per_token
    from drivewm.ar.folder import load_ar_folder
    from drivewm.ar.tokens import TokenDataset
    from drivewm.text import build_text_encoder

    model, cfg, tokenizer_dir = load_ar_folder(folder)
    train = TokenDataset(find_latent_cache(args.data, tokenizer_dir, None))
    held = TokenDataset(find_latent_cache(args.heldout, tokenizer_dir, None))
    return bits_per_token(model, build_text_encoder(cfg.text), train, held)


def score(family: str, folder: Path, args: argparse.Namespace, full: bool) -> dict:
    """The figures of one point (see the module docstring)."""
    scorer = Scorer(folder, args)
    out = {"video2world": video2world(scorer, heldout_clips(args.heldout, args.clips), args, full)}
    if full:
        out["turn"] = turn_sign(scorer, heldout_clips(args.heldout, args.turn_clips, straight=True), args)
        out["rollout"] = rollouts(scorer, heldout_clips(args.heldout, args.rollout_clips), args)
    if family == "ar" and (args.heldout / "latents").is_dir():
        out["bits"] = ar_bits(folder, args)
    out["sampling_cpu_s_per_window"] = float(np.median([c for c, _ in scorer.seconds]))
    out["sampling_wall_s_per_window"] = float(np.median([w for _, w in scorer.seconds]))
    return out


def run_family(family: str, args: argparse.Namespace) -> None:
    """Train and score ``family`` at each point of ``--cpu-seconds``; a rerun with the same ``--out`` goes on
    from its last scored point (points at or below it are skipped)."""
    out = args.out / family
    points = json.loads((out / "results.json").read_text()) if (out / "results.json").exists() else []
    budget = Budget(*(points[-1][k] for k in ("cpu_s", "steps", "calls"))) if points else Budget()
    for i, target in enumerate(args.cpu_seconds):
        if target <= budget.cpu_s:
            continue
        train_to(family, args, out, budget, target)
        full = i == len(args.cpu_seconds) - 1
        row = {**dataclasses.asdict(budget), "params": parameter_count(out), **score(family, out, args, full)}
        points.append(row)
        print(json.dumps({family: row}), flush=True)
        (out / "results.json").write_text(json.dumps(points, indent=1))


def print_table(run: Path) -> None:
    """One line per family and point; the last point's full figures below."""
    print("family     CPU-s  steps  params   V2W first (copy)  window (copy)  tokenizer  bits/token")
    for family in FAMILIES:
        path = run / family / "results.json"
        if not path.exists():
            continue
        points = json.loads(path.read_text())
        for p in points:
            v = p["video2world"]
            bits = f"{p['bits']['model']:.2f} (best baseline {p['bits']['best_baseline']:.2f})" if "bits" in p else "-"
            first = f"{v['first']:5.2f} ({v['copy_first']:5.2f}) dB"
            window = f"{v['window']:5.2f} ({v['copy_window']:5.2f}) dB"
            print(
                f"{family:9s} {p['cpu_s']:6.0f} {p['steps']:6d} {p['params'] / 1e6:5.2f}M  {first}  {window}  "
                f"{v['tokenizer_window']:5.2f} dB  {bits}"
            )
        print(f"  {family} at {points[-1]['cpu_s']:.0f} CPU-s: {json.dumps(points[-1])}")


def draw_figure(run: Path, path: Path) -> None:
    """Video2World window PSNR against training CPU-seconds per family, with copying the given frame and
    the tokenizer's reconstruction as lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.4), dpi=110)
    v = {}
    for family in FAMILIES:
        if (run / family / "results.json").exists():
            points = json.loads((run / family / "results.json").read_text())
            v = points[-1]["video2world"]
            label = f"{family} ({points[-1]['params'] / 1e6:.1f}M)"
            ax.plot([p["cpu_s"] for p in points], [p["video2world"]["window"] for p in points], "o-", label=label)
    if v:
        ax.axhline(v["copy_window"], ls="--", c="gray", label="copy the given frame")
        ax.axhline(v["tokenizer_window"], ls=":", c="k", label="tokenizer reconstruction")
    ax.set_xscale("log")
    ax.set_xlabel("training CPU-seconds (one thread, shared loaded machine)")
    ax.set_ylabel("Video2World window PSNR (dB)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, required=True, help="training clip folder with latents/TOKENIZER")
    parser.add_argument("--heldout", type=Path, required=True, help="held-out clip folder (other drives)")
    parser.add_argument("--tokenizer", type=Path, required=True, help="the FSQ tokenizer that encoded --data")
    parser.add_argument("--out", type=Path, required=True, help="run folder (model folders, results.json)")
    parser.add_argument("--cpu-seconds", type=lambda s: [float(x) for x in s.split(",")], default=[100, 200, 400, 800])
    parser.add_argument("--family", choices=[*FAMILIES, "both", "none"], default="both", help="none: table only")
    parser.add_argument("--ar-preset", default="debug")
    parser.add_argument("--dit-preset", default="debug")
    parser.add_argument("--clips", type=int, default=8, help="held-out clips for Video2World")
    parser.add_argument("--turn-clips", type=int, default=4, help="straight held-out clips, each turned both ways")
    parser.add_argument("--rollout-clips", type=int, default=2)
    parser.add_argument("--rollout-windows", type=int, default=4)
    parser.add_argument("--steps", type=int, default=20, help="diffusion sampler steps per window")
    parser.add_argument("--guidance", type=float, default=3.0, help="diffusion classifier-free guidance")
    parser.add_argument("--top-k", type=int, default=50, help="AR sampling top-k")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--figure", type=Path, default=None, help="PNG of the Video2World curve against compute")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    for family in FAMILIES if args.family == "both" else [args.family] if args.family != "none" else []:
        run_family(family, args)
    print_table(args.out)
    if args.figure:
        draw_figure(args.out, args.figure)


if __name__ == "__main__":
    main()
