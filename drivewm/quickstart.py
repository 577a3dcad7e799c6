"""``drivewm quickstart``: the whole pipeline on simulated data, through the public commands.

Each stage is the exact ``drivewm ...`` command a user would type (printed before it runs), with
the packaged recipes of each stage (``--recipe quickstart``). A stage that finished leaves a marker
in ``OUT/.stages/`` holding its command; a rerun skips it (and a changed command reruns it), so a
killed quickstart resumes where it stopped. The profile (package data,
``drivewm/recipes/quickstart.yaml``) gives each stage's arguments and expected time; ``smoke`` is
the few-minute version the tests run. The report (matplotlib) is imported when it is written, so
that ``drivewm --help`` stays fast.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
import time
from pathlib import Path

from drivewm import resources
from drivewm.atomic import write_json
from drivewm.cli import main
from drivewm.config import from_dict, load_yaml
from drivewm.errors import DrivewmError

RECIPE = resources.package_dir("recipes") / "quickstart.yaml"
FIRST_LOG = "{first_log}"  # stands for the first simulated log, known once simulate has run


@dataclasses.dataclass
class Generation:
    """One generated sample set: a prompt under a named (or file) ego trajectory."""

    name: str
    """Folder name under OUT/generated/."""
    prompt: str
    """Caption for every view."""
    trajectory: str = "straight"
    """straight|left|right|stop|FILE: the conditioned ego trajectory."""
    seed: int = 0
    """Sampler seed."""


@dataclasses.dataclass
class Profile:
    """A quickstart profile: extra arguments per stage (paths are filled in by quickstart)."""

    expected_minutes: float
    """What the profile takes on a 2-core CPU machine (printed at the start)."""
    rig: str
    """Rig of the simulated dataset, post-training, generation and eval."""
    simulate: list[str]
    curate: list[str]
    tokenizer_train: list[str]
    pretrain: list[str]
    posttrain: list[str]
    generate: list[str]
    eval: list[str]
    generations: list[Generation]
    paired: list[str]
    """``drivewm simulate`` arguments of the paired drives (with ``--conditions``) the transfer model trains on."""
    transfer_train: list[str]
    """``drivewm transfer-train`` arguments (post-trained from the quickstart's Text2World model)."""
    transfer: list[str]
    """``drivewm transfer`` arguments: the target condition and how many of the curated clips (the report shows one)."""


def load_profile(name: str, recipe: Path = RECIPE) -> Profile:
    """A quickstart profile by name (``full``, ``smoke``)."""
    profiles = load_yaml(recipe)
    if name not in profiles:
        raise DrivewmError(f"{recipe}: no quickstart profile {name!r} (has {sorted(profiles)})")
    return from_dict(Profile, profiles[name], f"{recipe}:{name}")


def stage_commands(p: Profile, out: Path) -> list[tuple[str, list[str]]]:
    """The pipeline as (stage name, drivewm argv) in order."""
    logs, clips, tok, t2w, mv, gen = (
        out / n for n in ("logs", "clips", "tokenizer", "text2world", "multiview", "generated")
    )
    stages = [
        ("simulate", ["simulate", *p.simulate, "--rig", p.rig, "--out", str(logs)]),
        ("view", ["view", FIRST_LOG, "--out", str(out / "drive.rrd")]),
        ("curate", ["curate", str(logs), "--out", str(clips), *p.curate]),
        ("tokenizer-train", ["tokenizer", "train", "--data", str(clips), "--out", str(tok), *p.tokenizer_train]),
        (
            "tokenizer-eval",
            [
                "tokenizer",
                "eval",
                "--model",
                str(tok),
                "--data",
                str(clips),
                "--out",
                str(out / "tokenizer_eval"),
                "--split",
                "holdout",
            ],
        ),
        ("tokenizer-encode", ["tokenizer", "encode", "--model", str(tok), "--data", str(clips)]),
        ("pretrain", ["pretrain", "--data", str(clips), "--tokenizer", str(tok), "--out", str(t2w), *p.pretrain]),
        (
            "posttrain",
            ["posttrain", "--init", str(t2w), "--data", str(clips), "--rig", p.rig, "--out", str(mv), *p.posttrain],
        ),
    ]
    for g in p.generations:
        argv = [
            "generate",
            "--model",
            str(mv),
            "--rig",
            p.rig,
            "--prompt",
            g.prompt,
            "--trajectory",
            g.trajectory,
            "--seed",
            str(g.seed),
            "--out",
            str(gen / g.name),
            *p.generate,
        ]
        stages.append((f"generate-{g.name}", argv))
    stages += transfer_stages(p, out)
    stages.append(("eval-real", ["eval", str(clips), "--rig", p.rig, "--out", str(out / "eval" / "real"), *p.eval]))
    for g in p.generations:
        stages.append(
            (
                f"eval-{g.name}",
                [
                    "eval",
                    str(gen / g.name),
                    "--rig",
                    p.rig,
                    "--out",
                    str(out / "eval" / g.name),
                    "--reference",
                    str(out / "eval" / "real" / "metrics.json"),
                    *p.eval,
                ],
            )
        )
    return stages


def transfer_stages(p: Profile, out: Path) -> list[tuple[str, list[str]]]:
    """Weather / time-of-day transfer (docs/transfer.md): paired drives, their latents, a transfer model
    post-trained from the Text2World model, and the first curated clips transferred."""
    logs, clips, model = out / "paired_logs", out / "paired_clips", out / "transfer_model"
    tok, t2w = out / "tokenizer", out / "text2world"
    return [
        ("simulate-paired", ["simulate", *p.paired, "--rig", p.rig, "--out", str(logs)]),
        ("curate-paired", ["curate", str(logs), "--out", str(clips), "--recipe", "transfer"]),
        ("tokenizer-encode-paired", ["tokenizer", "encode", "--model", str(tok), "--data", str(clips)]),
        (
            "transfer-train",
            ["transfer-train", "--init", str(t2w), "--data", str(clips), "--out", str(model), *p.transfer_train],
        ),
        (
            "transfer",
            ["transfer", str(out / "clips"), "--model", str(model), "--out", str(out / "transfer"), *p.transfer],
        ),
    ]


def run_stage(name: str, argv: list[str], out: Path, label: str = "quickstart") -> float:
    """Run one stage unless its marker says the same command finished; returns seconds spent."""
    logs = sorted((out / "logs").glob("*.mcap"))
    argv = [str(logs[0]) if a == FIRST_LOG and logs else a for a in argv]
    marker = out / ".stages" / f"{name}.json"
    if marker.is_file() and json.loads(marker.read_text()).get("argv") == argv:
        print(f"[{label}] {name}: done before, skipped")
        return 0.0
    print(f"[{label}] {name}: drivewm {shlex.join(argv)}", flush=True)
    tic = time.perf_counter()
    code = main(argv)
    if code:
        raise DrivewmError(f"{label} stage {name!r} failed (exit {code}); rerun {label} to resume from it")
    seconds = time.perf_counter() - tic
    write_json(marker, {"argv": argv, "seconds": seconds})
    return seconds


def quickstart(out: Path, profile_name: str = "full") -> Path:
    """Run every stage into ``out`` and write the report; returns the report's path."""
    from drivewm.report import write_report

    profile = load_profile(profile_name)
    stages = stage_commands(profile, out)
    print(
        f"[quickstart] profile {profile_name}: {len(stages)} stages, expected about "
        f"{profile.expected_minutes:.0f} minutes on a 2-core CPU machine; output in {out}",
        flush=True,
    )
    tic = time.perf_counter()
    for name, argv in stages:
        run_stage(name, argv, out)
    report = write_report(out, profile.rig, [g.name for g in profile.generations], stages)
    print(f"[quickstart] finished in {(time.perf_counter() - tic) / 60:.1f} min; report: {report}")
    return report


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("quickstart", help="simulate, curate, train every model, generate and evaluate; write a report")
    p.add_argument("--out", default="quickstart", help="output folder (a rerun resumes in it)")
    p.add_argument(
        "--profile",
        default="full",
        choices=sorted(load_yaml(RECIPE)),
        help="a profile of drivewm/recipes/quickstart.yaml: full (about 15 min on 2 cores) or smoke (a few minutes)",
    )
    p.set_defaults(func=lambda args: quickstart(Path(args.out), args.profile) and 0)
