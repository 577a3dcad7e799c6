"""``drivewm posttrain`` and ``drivewm rollout`` (thin: parse, build config, print it, call the library).
Multi-view ``drivewm generate`` lives in drivewm.multiview.generate (dispatched on model_type).
The models are imported inside the handlers, so that ``drivewm --help`` imports no PyTorch."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from drivewm import resources
from drivewm.choices import (
    add_guidance_interval_argument,
    add_registry_argument,
    at_least_one,
    model_folder,
    output_folder,
    seed,
)
from drivewm.diffusion.dit_config import DIT_PRESETS
from drivewm.multiview.defaults import DEFAULT_RESHADE, DEFAULT_SIGMA
from drivewm.recipe import add_recipe_arguments


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "posttrain", help="post-train a multi-view, trajectory-conditioned model from a Text2World model"
    )
    add_recipe_arguments(p, DIT_PRESETS, "debug", resources.names("recipes/posttrain"))
    p.add_argument(
        "--init",
        required=True,
        type=model_folder,
        help="Text2World folder to start from, or a multi-view folder to fine-tune (e.g. shipped:multiview)",
    )
    p.add_argument(
        "--data", required=True, type=Path, help="clip folder holding latents/NAME (or a latent cache folder)"
    )
    p.add_argument(
        "--rig", help="cameras to train on: rig name or YAML (default: the recipe's, else all cameras of the clips)"
    )
    p.add_argument(
        "--out", required=True, type=output_folder, help="model folder to write (resumes if it holds train_state.pt)"
    )
    p.add_argument(
        "--device",
        choices=["auto", "cpu", "cuda"],
        help="where to train (sets train.device; default: the recipe's, auto)",
    )
    p.set_defaults(func=posttrain_command)

    r = sub.add_parser("rollout", help="continue a real clip autoregressively under a chosen ego trajectory")
    r.add_argument(
        "--model",
        type=model_folder,
        help="multi-view model folder (with its tokenizer recorded); default: shipped:multiview",
    )
    r.add_argument("--clip", required=True, type=Path, help="clip shard (.tar) or clip folder")
    r.add_argument("--key", help="clip key inside --clip (default: the first clip)")
    r.add_argument(
        "--trajectory", default="straight", help="straight|left|right|stop or a waypoint file (.npy/.json, (N, 3) m)"
    )
    r.add_argument("--windows", type=int, default=2, help="windows to generate after the conditioning frames")
    r.add_argument(
        "--out", required=True, type=output_folder, help="output folder: clip shard, grid mp4, contact sheet"
    )
    r.add_argument("--prompt", default="", help="caption for every view (default: the clip's own captions)")
    r.add_argument(
        "--speed", type=float, default=0.0, help="speed of a named trajectory in m/s, at most 100 (default: the clip's)"
    )
    r.add_argument("--steps", type=int, default=35, help="sampler steps per window")
    r.add_argument("--guidance", type=float, default=7.0, help="classifier-free guidance scale")
    add_guidance_interval_argument(r)
    r.add_argument(
        "--trajectory-guidance",
        type=float,
        default=1.0,
        help="weigh the trajectory's effect this many times (1 = plain)",
    )
    add_reproject_arguments(r, None, f"{DEFAULT_SIGMA:g}")
    r.add_argument("--seed", type=seed, default=0, help="window w uses seed + w")
    add_registry_argument(
        r, "--sampler", "drivewm.diffusion.samplers:SAMPLERS", "EDM sampler (default heun)", default="heun"
    )
    r.add_argument(
        "--device", default="auto", choices=["auto", "cpu", "cuda"], help="where to run (auto: CUDA when available)"
    )
    r.set_defaults(func=rollout_command, lock_out="rollout")


def add_reproject_arguments(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup, default: float | None, default_text: str
) -> None:
    """``--reproject SIGMA`` and ``--reproject-steps N`` of generate and rollout (drivewm.multiview.reproject);
    ``default`` None leaves the choice to the command (``default_text`` says what it chooses)."""
    parser.add_argument(
        "--reproject",
        type=float,
        default=default,
        metavar="SIGMA",
        help="multi-view models: warp the first frame of every camera along the trajectory and refine it from "
        f"noise level SIGMA (0 = off; default {default_text}; docs/quality-vs-compute.md)",
    )
    parser.add_argument(
        "--reproject-steps", type=at_least_one, default=10, help="sampler steps of the refinement (default 10)"
    )
    parser.add_argument(
        "--reproject-walls",
        type=float,
        default=0.0,
        metavar="M",
        help="warp what stands beside the road as vertical walls M metres left and right of the first frame's "
        "ego instead of at infinity, so it passes by with parallax (default 0: road and infinity only; "
        "docs/quality-vs-compute.md, 'The flat-world warp stands still')",
    )
    parser.add_argument(
        "--reproject-reshade",
        action=argparse.BooleanOptionalAction,
        help="give the warped road of every frame the first frame's road colour at its own distance, so fog's "
        f"airlight is not pulled toward the camera (default {'on' if DEFAULT_RESHADE else 'off'}; "
        "docs/quality-vs-compute.md, 'Fog reads snow at --reproject 0.1')",
    )


def posttrain_command(args: argparse.Namespace) -> int:
    from drivewm.config import to_dict
    from drivewm.multiview.posttrain import RECIPES, posttrain

    overrides = [*([f"rig={args.rig}"] if args.rig else []), *args.overrides]
    overrides += [f"train.device={args.device}"] if args.device else []
    cfg = RECIPES.resolve(args.preset, args.recipe, overrides)
    print(json.dumps(to_dict(cfg), indent=2))
    if args.dry_run:
        return 0
    last = posttrain(cfg, args.init, args.data, args.out)
    print(f"wrote {args.out} ({json.dumps(last)})")
    return 0


def rollout_command(args: argparse.Namespace) -> int:
    from drivewm.errors import DrivewmError
    from drivewm.multiview.model import MultiView
    from drivewm.multiview.reproject import Reprojection
    from drivewm.multiview.rollout import RolloutOptions, load_clip, rollout
    from drivewm.multiview.writer import write_samples
    from drivewm.tokenizer import Tokenizer

    options = RolloutOptions(
        args.trajectory,
        args.windows,
        args.steps,
        args.guidance,
        args.trajectory_guidance,
        args.sampler,
        args.seed,
        args.prompt,
        args.speed,
        # sigma None: filled in by RolloutOptions
        Reprojection(args.reproject, args.reproject_steps, args.reproject_walls, args.reproject_reshade),
        args.guidance_interval,
    )
    if args.model is None:
        from drivewm.model_folders import shipped_model

        args.model = shipped_model("multiview")
    model = MultiView.from_pretrained(args.model).to(args.device)
    if not model.latent.tokenizer:
        raise DrivewmError(
            f"{args.model}: no tokenizer recorded in the model folder; a rollout needs one to encode the clip"
        )
    tokenizer = Tokenizer.from_pretrained(model.latent.tokenizer).to(model.device)
    sample = rollout(model, load_clip(args.clip, args.key), options, tokenizer)
    files = write_samples(args.out, [sample], model.latent.fps, name="rollout")
    print(f"wrote {len(files)} files to {args.out} ({sample.videos.shape[1]} frames per view)")
    return 0
