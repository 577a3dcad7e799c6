"""MODEL_CARD.md of exported weights, written from the run itself (nothing typed by hand but notes).

Sections, as a model card has them (Mitchell et al. 2019): the models (type, shape, parameters),
intended use and licence, the data (curation reports of the training and held-out clips), the recipe
(every stage's exact command from ``RUN/.stages/``, with its wall time), steps and compute of every
trained folder of the run (its training states), the evaluation: how the scored clips were sampled
(each generated clip's recorded sampler settings and ``post_processing``, so no post-processed figure
passes for the network's own frames) and the must-hold figures (``RUN/eval/figures.md`` of
:mod:`drivewm.product.figures`), the sha256 of every file, and the author's notes (deviations from the
recipe, limitations, what a figure predicts), given as a Markdown file.
"""

from __future__ import annotations

import math
import shlex
from collections import Counter
from pathlib import Path

from drivewm.atomic import read_jsonl, write_text
from drivewm.product.figures import read_json
from drivewm.product.quickstart import in_run
from drivewm.train.record import training_record

#: Config fields that say a network's size, in the card's models table.
SHAPE_KEYS = (
    "hidden_dim",
    "depth",
    "num_heads",
    "base_channels",
    "latent_channels",
    "temporal_compression",
    "spatial_compression",
)

#: What a generated clip's manifest row records of its sampling (drivewm.generate.config.GenerateConfig.record).
SAMPLING_KEYS = ("steps", "sampler", "guidance", "trajectory_guidance", "guidance_interval", "prompt_template")
#: The card's intended use and licence: every export is trained on simulated drives only.
INTENDED_USE = (
    "Research on multi-camera driving world models and tests of the drivewm pipeline: generating, transferring "
    "and scoring simulated drives. Trained on simulated drives only: not a model of real roads, "
    "and not for decisions in or about real vehicles. Licence: Apache-2.0, as drivewm's code."
)


def _models(out: Path) -> list[str]:
    from safetensors import safe_open

    rows = ["| folder | model type | shape | parameters |", "|---|---|---|---|"]
    for folder in sorted(p for p in out.iterdir() if (p / "config.json").is_file()):
        info = read_json(folder / "config.json")
        with safe_open(str(folder / "model.safetensors"), "pt") as f:
            params = sum(math.prod(f.get_slice(k).get_shape()) for k in f.keys())
        cfg = info.get("config", {})
        cfg = cfg.get("dit", cfg)  # a diffusion folder nests its network under dit
        shape = ", ".join(f"{k} {cfg[k]}" for k in SHAPE_KEYS if k in cfg)
        rows.append(f"| {folder.name}/ | {info.get('model_type', '?')} | {shape} | {params / 1e6:.2f}M |")
    return rows


def _data(run: Path) -> list[str]:
    rows = []
    for split in ("train", "heldout"):
        report = read_json(run / "clips" / split / "report.json")
        if report:
            rows.append(
                f"- {split}: {report.get('kept', 0)} clips from {report.get('logs_ok', 0)} simulated logs "
                f"(dropped by the filters: {report.get('dropped', {})})"
            )
    return rows


def _stages(run: Path) -> list[str]:
    rows = ["| stage | seconds | command |", "|---|---|---|"]
    for marker in sorted((run / ".stages").glob("*.json"), key=lambda p: p.stat().st_mtime):
        m = read_json(marker)
        seconds = "" if m.get("seconds") is None else f"{m['seconds']:.0f}"
        # paste-able for another run folder: the run's path when the stage ran as RUN
        command = shlex.join(in_run(m.get("argv", []), m.get("run") or run, "RUN"))
        rows.append(f"| {marker.stem} | {seconds} | `drivewm {command}` |")
    return rows


def _sampling(run: Path) -> list[str]:
    """How the generated clips the figures score were drawn: one line per distinct setting recorded in
    ``RUN/generated/*/manifest.jsonl`` (sampler settings, then the post-steps), with its clip count."""
    settings = Counter(
        _setting(row) for path in sorted((run / "generated").glob("*/manifest.jsonl")) for row in read_jsonl(path)
    )
    return [f"- {n} generated clip{'' if n == 1 else 's'}: {s}" for s, n in settings.items()] or [
        "- no generated clips"
    ]


def _setting(row: dict) -> str:
    """A generated clip's sampling and post-steps (its manifest row), in words."""
    sampling = ", ".join(f"{k} {row[k]}" for k in SAMPLING_KEYS if k in row) or "sampling not recorded"
    if "post_processing" not in row:
        return f"{sampling}; post-steps not recorded"
    steps = row["post_processing"]
    if not steps:
        return f"{sampling}; no post-steps (the network's own frames)"
    refine = ", ".join(f"{k} {v}" for k, v in (row.get("reproject") or {}).items())
    refine = f" (reproject {refine})" if refine else ""
    return (
        f"{sampling}; post-processed by {', '.join(steps)}{refine}: figures of the post-steps as much as of the network"
    )


def _compute(run: Path) -> list[str]:
    """Steps and wall seconds of every trained folder of the run (intermediate stages included:
    the image-pretrained Text2World model is compute the shipped one was built on)."""
    rows = []
    for state in sorted(run.glob("*/train_state.pt"), key=lambda p: p.stat().st_mtime):
        rec = training_record(state.parent)
        seconds = rec["train_seconds"]
        wall, hours = ("not recorded", "") if seconds is None else (f"{seconds:.0f}", f"{seconds / 3600:.2f}")
        rows.append(f"| {state.parent.name}/ | {rec['steps']} | {wall} | {hours} |")
    return rows


def write_model_card(run: Path, out: Path, manifest: dict, notes: str = "") -> Path:
    """Write ``out/MODEL_CARD.md`` for the weights exported from ``run``; returns its path."""
    run, out = Path(run), Path(out)
    compute = ["| run folder | steps | training wall seconds | wall hours |", "|---|---|---|---|"]
    compute += _compute(run)
    files = ["| file | bytes | sha256 |", "|---|---|---|"]
    files += [f"| {name} | {e['bytes']} | `{e['sha256']}` |" for name, e in manifest["files"].items()]
    figures = (run / "eval" / "figures.md").read_text() if (run / "eval" / "figures.md").is_file() else "not measured\n"
    text = "\n".join(
        [
            "# drivewm shipped models",
            "",
            "Written by `drivewm worldmodel export` from the training run; the figures are `drivewm eval`'s.",
            "",
            "## Models",
            "",
            *_models(out),
            "",
            "## Intended use and licence",
            "",
            INTENDED_USE,
            "",
            "## Data",
            "",
            *_data(run),
            "",
            "## Recipe",
            "",
            "`drivewm worldmodel train --profile cpu --out RUN` (drivewm/recipes/worldmodel.yaml); the stages as run:",
            "",
            *_stages(run),
            "",
            "## Steps and compute",
            "",
            *compute,
            "",
            "## Evaluation",
            "",
            "`drivewm eval` of the generated clips against the held-out clips' (docs/eval-protocol.md), as "
            "must-hold figures (drivewm.product.figures). The generated clips were sampled with:",
            "",
            *_sampling(run),
            "",
            figures,
            "## Files",
            "",
            *files,
            "",
            *(["## Notes", "", notes.strip(), ""] if notes.strip() else []),
        ]
    )
    path = out / "MODEL_CARD.md"
    write_text(path, text)
    return path
