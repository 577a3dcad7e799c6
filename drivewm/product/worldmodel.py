"""``drivewm worldmodel``: the one-command recipe that trains the models drivewm ships, and their export.

``drivewm worldmodel train --profile cpu --out RUN`` runs every stage through the public commands
(printed before each runs), resumable by stage like the quickstart (``RUN/.stages/``) and inside
each training stage by its own train state:

1. simulate the training drives and the held-out drives (packaged simulate recipes ``worldmodel``
   and ``worldmodel_heldout``);
2. curate both (curate recipe ``worldmodel``: 160x96 per camera, 17 frames at 10 fps);
3. train the tokenizer, score it on the held-out drives, encode both clip sets;
4. Text2World pretraining in Cosmos' progressive order: images (the first latent frame of every
   view), then video warm-started from the image model;
5. multi-view post-training of the nuScenes-like rig from the video model, with Video2World and
   trajectory conditioning;
6. generate the benchmark clips (prompts and trajectories the training captions never use
   verbatim, fixed seeds) and score them next to the held-out clips with ``drivewm eval``;
7. the must-hold figures against their goals (``drivewm worldmodel figures``,
   drivewm/product/figures.py): ``RUN/eval/figures.json`` and ``figures.md``;
8. (profile key ``transfer_train``) paired drives, every drive in six conditions, training and
   held-out, and a weather / time-of-day transfer model post-trained from the video Text2World model
   (docs/transfer.md), scored by ``benchmarks/bench_transfer.py``.

Profiles (``drivewm/recipes/worldmodel.yaml``) change only sizes and steps: ``cpu`` is what the shipped
weights were trained with on 2 cores; ``gpu`` is the same recipe sized for one GPU in about 25
minutes (``scripts/gpu-recipe.sh``). ``drivewm worldmodel benchmark --model MVDIR --heldout CLIPS --out
RUN`` runs steps 6 and 7 alone on any multi-view model folder (a fleet fine-tune of the shipped one, a
GPU run), so its figures compare with the model card's. ``drivewm worldmodel export RUN --out DIR`` writes the three
model folders (four with the transfer model of the paired-drive stages) in fp16 safetensors with a
model card (what ``drivewm/weights/`` ships).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from drivewm import resources
from drivewm.choices import output_folder, whole_number
from drivewm.errors import DrivewmError

PROFILES = resources.package_dir("recipes") / "worldmodel.yaml"


@dataclasses.dataclass
class Benchmark:
    """One generated set of the benchmark: a prompt under a named trajectory, ``samples`` seeds."""

    name: str
    """Folder name under RUN/generated/."""
    prompt: str
    """Caption for every view (never a training caption verbatim)."""
    trajectory: str = "straight"
    """straight|left|right|stop."""
    seed: int = 0
    """First sampler seed."""


@dataclasses.dataclass
class WorldModelProfile:
    """Extra arguments per stage (paths are filled in by :func:`stage_commands`)."""

    rig: str
    """Rig of the dataset, post-training, generation and eval."""
    simulate_train: list[str]
    simulate_heldout: list[str]
    curate: list[str]
    tokenizer_train: list[str]
    pretrain_image: list[str]
    pretrain_video: list[str]
    posttrain: list[str]
    generate: list[str]
    eval: list[str]
    eval_heldout: list[str] = dataclasses.field(default_factory=list)
    """Extra arguments of the held-out reference eval (e.g. ``--max-clips``)."""
    transfer_train: list[str] | None = None
    """Arguments of ``drivewm transfer-train`` from the video Text2World model on paired drives
    (simulate recipes ``transfer`` / ``transfer_heldout``, curate recipe ``transfer``, docs/transfer.md);
    None: the run trains no transfer model."""
    samples_per_benchmark: int = 2
    """Seeds per benchmark entry (24+ generated clips in all for the issue's figures)."""
    benchmarks: list[Benchmark] = dataclasses.field(default_factory=list)
    """What is generated and scored."""


def load_profile(name: str, path: Path = PROFILES) -> WorldModelProfile:
    from drivewm.config import from_dict, load_yaml

    profiles = load_yaml(path)
    if name not in profiles:
        raise DrivewmError(f"{path}: no worldmodel profile {name!r} (has {sorted(profiles)})")
    return from_dict(WorldModelProfile, profiles[name], f"{path}:{name}")


def stage_commands(p: WorldModelProfile, run: Path) -> list[tuple[str, list[str]]]:
    """The recipe as (stage name, drivewm argv) in order."""
    logs, clips, tok = run / "logs", run / "clips", run / "tokenizer"
    img, vid, mv, ev = run / "text2world_image", run / "text2world", run / "multiview", run / "eval"
    stages = [
        ("simulate-train", ["simulate", *p.simulate_train, "--rig", p.rig, "--out", str(logs / "train")]),
        ("simulate-heldout", ["simulate", *p.simulate_heldout, "--rig", p.rig, "--out", str(logs / "heldout")]),
        ("curate-train", ["curate", str(logs / "train"), "--out", str(clips / "train"), *p.curate]),
        ("curate-heldout", ["curate", str(logs / "heldout"), "--out", str(clips / "heldout"), *p.curate]),
        (
            "tokenizer-train",
            ["tokenizer", "train", "--data", str(clips / "train"), "--out", str(tok), *p.tokenizer_train],
        ),
        (
            "tokenizer-eval",
            [
                "tokenizer",
                "eval",
                "--model",
                str(tok),
                "--data",
                str(clips / "heldout"),
                "--out",
                str(ev / "tokenizer"),
            ],
        ),
        ("encode-train", ["tokenizer", "encode", "--model", str(tok), "--data", str(clips / "train")]),
        ("encode-heldout", ["tokenizer", "encode", "--model", str(tok), "--data", str(clips / "heldout")]),
        (
            "pretrain-image",
            [
                "pretrain",
                "--data",
                str(clips / "train"),
                "--tokenizer",
                str(tok),
                "--out",
                str(img),
                "--set",
                "data.frames=1",
                *p.pretrain_image,
            ],
        ),
        (
            "pretrain-video",
            [
                "pretrain",
                "--data",
                str(clips / "train"),
                "--tokenizer",
                str(tok),
                "--init",
                str(img),
                "--out",
                str(vid),
                *p.pretrain_video,
            ],
        ),
        (
            "posttrain",
            [
                "posttrain",
                "--init",
                str(vid),
                "--data",
                str(clips / "train"),
                "--rig",
                p.rig,
                "--out",
                str(mv),
                *p.posttrain,
            ],
        ),
    ]
    stages += benchmark_stages(p, str(mv), run, clips / "heldout")
    if p.transfer_train is not None:
        stages += transfer_stages(p, run)
    return stages


def generate_recipe(run: Path, recipe: str | None, overrides: list[str]) -> Path | None:
    """The generate recipe every benchmark sample is drawn with: ``recipe`` and ``overrides`` resolved
    (drivewm.generate.config.RECIPES, so a bad value fails before the first stage) and written in full to
    ``RUN/generate-HASH.yaml``, named by its content so that a rerun with other settings runs the generate
    stages again; None (generate's defaults, the network's own frames) when neither is given."""
    if recipe is None and not overrides:
        return None
    import hashlib

    import yaml

    from drivewm.atomic import write_bytes
    from drivewm.config import to_dict
    from drivewm.generate.config import RECIPES

    text = yaml.safe_dump({"config": to_dict(RECIPES.resolve(None, recipe, overrides))}, sort_keys=True)
    path = run / f"generate-{hashlib.sha256(text.encode()).hexdigest()[:12]}.yaml"
    write_bytes(path, text.encode())
    return path


def benchmark_stages(
    p: WorldModelProfile,
    model: str,
    run: Path,
    heldout: Path,
    samples: int | None = None,
    recipe: Path | None = None,
) -> list[tuple[str, list[str]]]:
    """The benchmark of multi-view model ``model`` as (stage name, drivewm argv): the profile's prompts
    generated into ``RUN/generated/NAME`` (``samples`` seeds each from the prompt's first, default the
    profile's; seeds are per sample, so more samples keep the first ones' bytes; drawn with the generate
    ``recipe``, default generate's own), the held-out clips ``heldout`` and the generated ones scored into
    ``RUN/eval``, and the must-hold figures."""
    gen, ev = run / "generated", run / "eval"
    samples = samples or p.samples_per_benchmark
    stages = []
    for b in p.benchmarks:
        argv = ["generate", "--model", model, "--rig", p.rig, "--prompt", b.prompt, "--trajectory", b.trajectory]
        argv += ["--seed", str(b.seed), "--num-samples", str(samples), "--out", str(gen / b.name)]
        argv += ["--recipe", str(recipe)] if recipe is not None else []
        stages.append((f"generate-{b.name}", [*argv, *p.generate]))
    stages.append(
        ("eval-heldout", ["eval", str(heldout), "--rig", p.rig, "--out", str(ev / "heldout"), *p.eval, *p.eval_heldout])
    )
    reference = ["--reference", str(ev / "heldout" / "metrics.json")]
    stages.append(
        ("eval-generated", ["eval", str(gen), "--rig", p.rig, "--out", str(ev / "generated"), *reference, *p.eval])
    )
    stages.append(("figures", ["worldmodel", "figures", str(run)]))
    return stages


def benchmark_worldmodel(
    model: str,
    heldout: Path,
    run: Path,
    profile_name: str,
    samples: int | None,
    tokenizer_eval: Path | None,
    recipe: str | None = None,
    overrides: list[str] = (),
) -> None:
    """Run (or resume) the benchmark of ``model`` into ``run``: the shipped models' figures for any
    multi-view model folder (a fleet fine-tune, a GPU run), against ``heldout`` clips of its rig, or
    against the held-out eval an earlier benchmark wrote (``heldout`` its metrics.json: copied to
    ``RUN/eval/heldout/`` and not evaluated again, so fine-tunes compared on it share one reference)."""
    from drivewm.atomic import write_json
    from drivewm.model_folders import resolve_model_folder
    from drivewm.product.quickstart import run_stage, stage_marker

    folder = resolve_model_folder(model)  # a missing folder fails here, not at the first of twelve stages
    if not (folder / "config.json").is_file():
        raise DrivewmError(f"worldmodel benchmark: --model {model} is not a model folder (no config.json)")
    if not heldout.is_dir() and not heldout.is_file():
        raise DrivewmError(f"worldmodel benchmark: --heldout {heldout} is not a clip folder or an eval's metrics.json")
    profile = load_profile(profile_name)
    reference = _read_metrics(heldout, "--heldout", "`drivewm eval`", "clips") if heldout.is_file() else None
    tokenizer = (
        _read_metrics(tokenizer_eval, "--tokenizer-eval", "`tokenizer eval`", "psnr") if tokenizer_eval else None
    )
    if reference is not None:
        write_json(run / "eval" / "heldout" / "metrics.json", reference)
    if tokenizer is not None:  # the tokenizer's held-out PSNR figure, from its own eval
        write_json(run / "eval" / "tokenizer" / "metrics.json", tokenizer)
        # a rerun that brings the tokenizer's eval must read it: the figures stage's command is unchanged
        stage_marker(run, "figures").unlink(missing_ok=True)
    stages = benchmark_stages(profile, model, run, heldout, samples, generate_recipe(run, recipe, list(overrides)))
    if reference is not None:
        stages = [(name, argv) for name, argv in stages if name != "eval-heldout"]
    print(f"[worldmodel] benchmark of {model}, profile {profile_name}: {len(stages)} stages into {run}", flush=True)
    for name, argv in stages:
        run_stage(name, argv, run, "worldmodel")


def _read_metrics(path: Path, flag: str, what: str, key: str) -> dict:
    """The JSON object of metrics file ``path``, which must hold ``key``; DrivewmError naming ``flag`` else."""
    import json

    try:
        metrics = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise DrivewmError(f"worldmodel benchmark: {flag} {path}: {exc}") from None
    if not isinstance(metrics, dict) or key not in metrics:
        raise DrivewmError(f"worldmodel benchmark: {path} is not a {what} metrics.json")
    return metrics


def transfer_stages(p: WorldModelProfile, run: Path) -> list[tuple[str, list[str]]]:
    """Paired drives (training and held-out), their clips and latents, and the transfer model
    post-trained from ``RUN/text2world``; ``benchmarks/bench_transfer.py --model RUN/transfer --data
    RUN/clips/paired_heldout`` scores it (docs/transfer.md)."""
    logs, clips, tok = run / "logs", run / "clips", run / "tokenizer"
    stages = []
    for split, recipe in (("paired", "transfer"), ("paired_heldout", "transfer_heldout")):
        name = split.replace("_", "-")
        stages.append(
            (f"simulate-{name}", ["simulate", "--recipe", recipe, "--rig", p.rig, "--out", str(logs / split)])
        )
        stages.append(
            (f"curate-{name}", ["curate", str(logs / split), "--out", str(clips / split), "--recipe", "transfer"])
        )
        stages.append((f"encode-{name}", ["tokenizer", "encode", "--model", str(tok), "--data", str(clips / split)]))
    train = ["transfer-train", "--init", str(run / "text2world"), "--data", str(clips / "paired")]
    stages.append(("transfer-train", [*train, "--out", str(run / "transfer"), *p.transfer_train]))
    return stages


def train_worldmodel(run: Path, profile_name: str) -> None:
    """Run (or resume) every stage of the recipe into ``run``."""
    from drivewm.product.quickstart import run_stage

    profile = load_profile(profile_name)
    stages = stage_commands(profile, run)
    print(f"[worldmodel] profile {profile_name}: {len(stages)} stages into {run}", flush=True)
    for name, argv in stages:
        run_stage(name, argv, run, "worldmodel")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("worldmodel", help="train the models drivewm ships (one recipe, resumable), or export them")
    wsub = p.add_subparsers(dest="worldmodel_command", metavar="ACTION", required=True)
    t = wsub.add_parser("train", help="simulate, curate, train tokenizer/Text2World/multi-view, generate, evaluate")
    t.add_argument("--profile", default="cpu", help="cpu (the shipped weights) or gpu (one GPU, ~25 minutes)")
    t.add_argument("--out", required=True, type=output_folder, help="run folder (a rerun resumes in it)")
    t.set_defaults(func=lambda args: train_worldmodel(args.out, args.profile))
    f = wsub.add_parser("figures", help="the must-hold figures of a run's evals: RUN/eval/figures.json and .md")
    f.add_argument("run", type=Path, help="run folder of `drivewm worldmodel train`")
    f.set_defaults(func=_figures)
    b = wsub.add_parser(
        "benchmark",
        help="the shipped models' benchmark on any multi-view model: generate its prompts, eval, figures",
    )
    b.add_argument("--model", default="shipped:multiview", help="multi-view model folder (default shipped:multiview)")
    b.add_argument(
        "--heldout",
        required=True,
        type=Path,
        help="held-out clips of the model's rig and size (e.g. the worldmodel_heldout simulate recipe, "
        "curated with --recipe worldmodel), or the metrics.json of their eval from an earlier benchmark "
        "(RUN/eval/heldout/metrics.json: reused, not evaluated again)",
    )
    b.add_argument("--out", required=True, type=output_folder, help="run folder (a rerun resumes in it)")
    b.add_argument("--profile", default="cpu", help="profile whose prompts, sampler and eval settings to use")
    b.add_argument(
        "--samples-per-prompt",
        type=whole_number(1, 64),
        help="seeds per prompt (default the profile's, 2: 24 clips; 4 reads the turn sign on 32 left/right samples)",
    )
    b.add_argument("--tokenizer-eval", type=Path, help="a `tokenizer eval` metrics.json for the PSNR figure")
    b.add_argument(
        "--recipe",
        help="generate recipe every sample is drawn with (drivewm generate --recipe; a packaged name, e.g. "
        "reprojected, or a YAML file; default generate's: the network's own frames)",
    )
    b.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE", help="override a generate field"
    )
    b.set_defaults(
        func=lambda args: benchmark_worldmodel(
            args.model,
            args.heldout,
            args.out,
            args.profile,
            args.samples_per_prompt,
            args.tokenizer_eval,
            args.recipe,
            args.overrides,
        )
    )
    m = wsub.add_parser(
        "interpolate",
        help="mix a fine-tune with the model it started from: (1 - alpha) * BASE + alpha * TUNED (WiSE-FT)",
    )
    m.add_argument("base", help="the model the fine-tune started from (e.g. shipped:multiview)")
    m.add_argument("tuned", help="the fine-tuned model folder (same model type and tensors)")
    m.add_argument("--alpha", required=True, type=float, help="0 = BASE, 1 = TUNED")
    m.add_argument(
        "--config-from", choices=("base", "tuned"), default="tuned", help="whose config and latent settings to keep"
    )
    m.add_argument("--out", required=True, type=output_folder, help="model folder to write")
    m.set_defaults(func=_interpolate)
    e = wsub.add_parser("export", help="fp16 model folders + model card from a finished run")
    e.add_argument("run", type=Path, help="run folder of `drivewm worldmodel train`")
    e.add_argument(
        "--out", required=True, type=output_folder, help="where to write tokenizer/, text2world/, multiview/"
    )
    e.add_argument("--notes", type=Path, help="Markdown file: the model card's notes (deviations, predictions)")
    e.set_defaults(func=_export)


def _figures(args: argparse.Namespace) -> int:
    from drivewm.product.figures import write_figures

    write_figures(args.run)
    return 0


def _interpolate(args: argparse.Namespace) -> int:
    from drivewm.product.release import interpolate_folders

    print(interpolate_folders(args.base, args.tuned, args.alpha, args.out, args.config_from))
    return 0


def _export(args: argparse.Namespace) -> int:
    from drivewm.product.release import export_run

    notes = args.notes.read_text() if args.notes else ""
    for path in export_run(args.run, args.out, notes):
        print(path)
    return 0
