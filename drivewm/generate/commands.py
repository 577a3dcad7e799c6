"""``drivewm generate`` and ``drivewm rollout`` (thin: parse, build the GenerateConfig, print it, call the generator).

Settings come from one place, :class:`drivewm.generate.config.GenerateConfig`, resolved by the recipe
mechanism (``--recipe``, ``--set``); each shortcut flag of :data:`SHORTCUTS` is ``--set`` of one field.
The model folder's ``model_type`` picks the generator (drivewm.generate.registry). Torch is imported
inside the handlers, so that ``drivewm --help`` imports none.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path

from drivewm import resources
from drivewm.choices import at_least_one, model_folder, output_folder, seed
from drivewm.recipe import add_recipe_arguments

#: Shortcut flags by dest (``--num-samples`` is ``num_samples``) -> (config field, argparse type, help);
#: each one given is ``--set FIELD=VALUE``, after the recipe and before ``--set``.
SHORTCUTS = {
    "steps": ("sampling.steps", at_least_one, "sampler steps (default 35)"),
    "guidance": ("sampling.guidance", float, "classifier-free guidance scale (default 7)"),
    "trajectory_guidance": ("sampling.trajectory_guidance", float, "weigh the trajectory's effect (default 1)"),
    "sampler": ("sampling.sampler", str, "heun (default) or euler"),
    "seed": ("sampling.seed", seed, "sample (rollout: window) i uses seed + i (default 0)"),
    "trajectory": ("trajectory", str, "straight|left|right|stop or a waypoint file (N, 3) m (default straight)"),
    "device": ("device", str, "auto (default: CUDA when available), cpu or cuda"),
    "num_samples": ("num_samples", at_least_one, "samples per prompt (default 1)"),
    "rig": ("rig", str, "camera rig name or YAML (default: the model's training rig)"),
    "windows": ("rollout.windows", at_least_one, "windows generated after the conditioning frames (default 2)"),
    "speed": ("rollout.speed_mps", float, "speed of a named trajectory, m/s (default: the clip's)"),
}
COMMON = ("steps", "guidance", "trajectory_guidance", "sampler", "seed", "trajectory", "device")
GENERATE_SHORTCUTS = (*COMMON, "num_samples", "rig")
ROLLOUT_SHORTCUTS = (*COMMON, "windows", "speed")


def register(sub: argparse._SubParsersAction) -> None:
    g = sub.add_parser("generate", help="generate clips from a model folder (Text2World or multi-view)")
    g.add_argument("--model", type=model_folder, help="model folder or shipped:KIND (default shipped:multiview)")
    g.add_argument("--prompt", required=True, action="append", help="caption (repeat for several)")
    g.add_argument("--out", required=True, type=output_folder, help="output folder: clip shards, mp4s, contact sheet")
    g.add_argument("--condition-clip", type=Path, help="clip whose first frames condition every sample (Video2World)")
    g.add_argument("--layout", type=Path, help="clip folder: regenerate its clips' drives from their layouts")
    g.add_argument("--scenario", help="highway|merge|roundabout|intersection|grid|spider|random or a simulate YAML")
    add_config_arguments(g, GENERATE_SHORTCUTS)
    g.set_defaults(func=generate_command, lock_out="generate")

    r = sub.add_parser("rollout", help="continue a real clip autoregressively under a chosen ego trajectory")
    r.add_argument("--model", type=model_folder, help="multi-view model folder (default shipped:multiview)")
    r.add_argument("--clip", required=True, type=Path, help="clip shard (.tar) or clip folder")
    r.add_argument("--key", help="clip key inside --clip (default: the first clip)")
    r.add_argument("--out", required=True, type=output_folder, help="output folder: clip shard, grid mp4, sheet")
    r.add_argument("--prompt", default="", help="caption for every view (default: the clip's own captions)")
    add_config_arguments(r, ROLLOUT_SHORTCUTS)
    r.set_defaults(func=rollout_command, lock_out="rollout")


def add_config_arguments(parser: argparse.ArgumentParser, shortcuts: tuple[str, ...]) -> None:
    """The ``shortcuts`` flags (default None: the config's), then ``--recipe``, ``--set`` and ``--dry-run``."""
    for dest in shortcuts:
        _, kind, text = SHORTCUTS[dest]
        parser.add_argument(f"--{dest.replace('_', '-')}", type=kind, metavar=dest.upper(), help=text)
    parser.set_defaults(shortcuts=shortcuts)
    add_recipe_arguments(parser, ["default"], "default", resources.names("recipes/generate"))


def resolve_config(args: argparse.Namespace):
    """The GenerateConfig of a command line: recipe, then the shortcut flags given, then ``--set``."""
    from drivewm.generate.config import RECIPES

    given = [(SHORTCUTS[d][0], getattr(args, d)) for d in args.shortcuts if getattr(args, d) is not None]
    shortcuts = [f"{field}={yaml_scalar(value)}" for field, value in given]
    book = dataclasses.replace(RECIPES, stage=args.command)  # errors name the command run
    return book.resolve(None, args.recipe, [*shortcuts, *args.overrides])


def yaml_scalar(value: int | float | str) -> str:
    """``value`` as the YAML scalar ``--set`` parses back to it (NaN and infinities included)."""
    if isinstance(value, float) and not math.isfinite(value):
        return ".nan" if math.isnan(value) else ("-.inf" if value < 0 else ".inf")
    return json.dumps(value)


def start(args: argparse.Namespace):
    """The resolved config, printed; None for ``--dry-run``. Fills in the default model folder."""
    from drivewm.config import to_dict

    cfg = resolve_config(args)
    print(json.dumps(to_dict(cfg), indent=2))
    if args.model is None:
        from drivewm.model_folders import shipped_model

        args.model = shipped_model("multiview")
    return None if args.dry_run else cfg


def generate_command(args: argparse.Namespace) -> int:
    from drivewm.errors import DrivewmError
    from drivewm.generate.protocol import GenerateRequest
    from drivewm.generate.registry import load_generator

    cfg = start(args)
    if cfg is None:
        return 0
    request = GenerateRequest(args.prompt, args.condition_clip, args.layout, args.scenario)
    generator = load_generator(args.model, cfg.device)
    refused = [name for name in request.given() if name not in generator.inputs]
    if refused:
        raise DrivewmError(f"{args.model}: a {generator.model_type} model takes no {', '.join(refused)}")
    files = generator.write(generator.generate(request, cfg), args.out)
    print(f"wrote {len(files)} files to {args.out}")
    return 0


def rollout_command(args: argparse.Namespace) -> int:
    from drivewm.generate.registry import load_generator
    from drivewm.generate.rollout import load_clip

    cfg = start(args)
    if cfg is None:
        return 0
    generator = load_generator(args.model, cfg.device)
    sample = generator.rollout(load_clip(args.clip, args.key), cfg, args.prompt)
    files = generator.write([sample], args.out, name="rollout")
    print(f"wrote {len(files)} files to {args.out} ({sample.videos.shape[1]} frames per view)")
    return 0
