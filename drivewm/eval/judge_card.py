"""Shipping the layout judge: ``drivewm/weights/judge`` (fp16) with its model card, in the manifest.

:func:`ship_judge` exports a judge run folder through drivewm.product.release.replace_shipped, writes
``judge/MODEL_CARD.md`` from the run (network, data, steps, compute) and a ``drivewm judge eval``
report of the held-out clips (per-class IoU, mIoU per condition), adds the card to ``MANIFEST.json``,
and lists the judge's files with their sha256 in the shipped ``MODEL_CARD.md`` (its "Layout judge"
section, rewritten on every ship).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from drivewm.atomic import write_json, write_text
from drivewm.model_folders import WEIGHTS_DIR
from drivewm.product.release import folder_files, manifest_files, replace_shipped
from drivewm.train.checkpoint import load_model_folder, load_train_state

CARD_NAME = "MODEL_CARD.md"
SECTION = "## Layout judge"


def _fmt(value: float | None) -> str:
    return "n/a" if value is None or not math.isfinite(value) else f"{value:.3f}"


def card_text(run: Path, report: dict, notes: str) -> str:
    """The judge's model card: network, data, recipe, compute and the held-out figures of ``report``."""
    info, state = load_model_folder(run, "judge")
    saved = load_train_state(run) or {}
    config = saved.get("config", {})
    params = sum(t.numel() for t in state.values())
    rows = [f"| {name} | {_fmt(iou)} |" for name, iou in report["iou"].items()]
    by_condition = report["by_condition"].items()
    conditions = [f"| {name} | {_fmt(s['miou'])} | {_fmt(s['pixel_accuracy'])} |" for name, s in by_condition]
    return "\n".join(
        [
            "# drivewm layout judge",
            "",
            "A compact U-Net (drivewm/eval/judge.py) that reads the renderer's label classes back from a camera frame;",
            "`drivewm judge score` uses it to measure how well generated frames keep the layout they were asked for.",
            "",
            f"- network: {json.dumps(info['config'])}, {params} parameters, fp16",
            f"- data: {config.get('frames', '?')} labelled frames (every {config.get('frame_stride', '?')}th) of "
            f"{', '.join(Path(p).name for p in config.get('data', []))}",
            f"- training: {int(saved.get('step', 0))} steps of {config.get('train', {}).get('batch_size', '?')} crops "
            f"{config.get('crop_hw')}, {saved.get('train_seconds', 0.0):.0f} s on the CPU; run config in the card's "
            "run folder (train_state.pt)",
            "",
            f"## Held-out figures ({report['frames']} frames of {', '.join(Path(p).name for p in report['data'])})",
            "",
            f"mIoU {_fmt(report['miou'])}, pixel accuracy {_fmt(report['pixel_accuracy'])}.",
            "",
            "| class | IoU |",
            "|---|---|",
            *rows,
            "",
            "| condition | mIoU | pixel accuracy |",
            "|---|---|---|",
            *conditions,
            "",
            *(["## Notes", "", notes.strip(), ""] if notes.strip() else []),
        ]
    )


def ship_judge(run: str | Path, report: dict, notes: str = "", root: Path = WEIGHTS_DIR) -> dict:
    """Ship the judge of ``run`` with its card (figures from the eval ``report``); returns the manifest."""
    run = Path(run)
    replace_shipped("judge", run, root)
    write_text(root / "judge" / CARD_NAME, card_text(run, report, notes))
    manifest = json.loads((root / "MANIFEST.json").read_text())
    folders = {p.name: p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")}
    manifest["files"] = manifest_files(root, folder_files(root, folders))
    write_json(root / "MANIFEST.json", manifest)
    _list_in_shipped_card(root / CARD_NAME, {k: v for k, v in manifest["files"].items() if k.startswith("judge/")})
    return manifest


def _list_in_shipped_card(card: Path, files: dict) -> None:
    """Rewrite the shipped card's judge section (the last section) with ``files``' bytes and sha256."""
    text = card.read_text()
    text = text.split(f"\n{SECTION}\n")[0].rstrip("\n")
    rows = [f"| {name} | {e['bytes']} | `{e['sha256']}` |" for name, e in files.items()]
    section = [SECTION, "", "The layout judge's own card: judge/MODEL_CARD.md.", "", "| file | bytes | sha256 |"]
    write_text(card, "\n".join([text, "", *section, "|---|---|---|", *rows, ""]))
