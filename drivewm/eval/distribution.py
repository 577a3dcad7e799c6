"""FID and FVD of generated clips against real ones: per view and over all views, each with its counts.

FID compares Inception features of single frames (every ``frame_step``-th frame of every clip),
FVD I3D features of the first ``fvd_frames`` frames of each clip and view (drivewm.eval.feature_nets).
"All views" pools the features of every view shared by both sets. Each figure is a
:class:`drivewm.eval.frechet.DistributionFigure`: value, bootstrap interval and sample counts.
Features are computed clip by clip, so only features (not videos) are held.
"""

from __future__ import annotations

import dataclasses
from collections import defaultdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

from drivewm.atomic import write_json, write_text
from drivewm.errors import DrivewmError
from drivewm.eval.feature_nets import I3DFeatures, InceptionFeatures
from drivewm.eval.frechet import frechet_with_interval
from drivewm.eval.inputs import EvalItem

ALL_VIEWS = "all"
"""Key of the figure over all views pooled."""


@dataclasses.dataclass
class DistributionConfig:
    """FID / FVD protocol."""

    fvd_frames: int = 16
    """Frames per clip fed to I3D (FVD's 16, Unterthiner et al. 2018); shorter clips are left out of FVD."""
    frame_step: int = 1
    """FID uses every this-many-th frame of each clip."""
    bootstrap: int = 50
    """Bootstrap resamples of each interval."""
    confidence: float = 0.95
    """Coverage of each interval."""
    seed: int = 0
    """Seed of the bootstrap resampling."""

    def validate(self) -> None:
        if self.fvd_frames < 1 or self.frame_step < 1 or self.bootstrap < 0 or not 0 < self.confidence < 1:
            raise DrivewmError(f"distribution config: {self} needs fvd_frames, frame_step >= 1, 0 < confidence < 1")


@dataclasses.dataclass
class FeatureSet:
    """Per view: FID features of frames and FVD features of clips; clips too short for FVD counted."""

    fid: dict[str, list[np.ndarray]] = dataclasses.field(default_factory=lambda: defaultdict(list))
    fvd: dict[str, list[np.ndarray]] = dataclasses.field(default_factory=lambda: defaultdict(list))
    short_clips: int = 0


def collect_features(items: list[EvalItem], inception, i3d, cfg: DistributionConfig, label: str) -> FeatureSet:
    """Features of every readable clip; unreadable ones are refused by name (a silently smaller set
    would move both figures)."""
    out = FeatureSet()
    for item in tqdm(items, desc=f"features ({label})", unit="clip"):
        try:
            videos = item.videos()
        except DrivewmError as exc:
            raise DrivewmError(f"{label}: {exc}") from None
        for view, video in videos.items():
            if inception is not None:
                out.fid[view].append(inception(video[:: cfg.frame_step]))
            if i3d is not None:
                if len(video) >= cfg.fvd_frames:
                    out.fvd[view].append(i3d([video[: cfg.fvd_frames]]))
                else:
                    out.short_clips += 1
    return out


def _figures(gen: dict, real: dict, cfg: DistributionConfig) -> dict:
    views = [v for v in gen if v in real]
    figures = {}
    for view in [*views, ALL_VIEWS]:
        chosen = views if view == ALL_VIEWS else [view]
        if not chosen:
            continue
        g = np.concatenate([f for v in chosen for f in gen[v]])
        r = np.concatenate([f for v in chosen for f in real[v]])
        try:
            fig = frechet_with_interval(g, r, cfg.bootstrap, cfg.confidence, cfg.seed)
        except DrivewmError as exc:
            figures[view] = {"value": None, "num_generated": len(g), "num_real": len(r), "error": str(exc)}
            continue
        figures[view] = {**dataclasses.asdict(fig), "text": fig.text()}
    return figures


def distribution_metrics(
    generated: list[EvalItem],
    real: list[EvalItem],
    inception_path: str | Path | None,
    i3d_path: str | Path | None,
    cfg: DistributionConfig | None = None,
) -> dict:
    """``{"fid": {view: figure}, "fvd": {view: figure}, ...}`` with figure dicts of value, interval and counts."""
    cfg = cfg or DistributionConfig()
    cfg.validate()
    if inception_path is None and i3d_path is None:
        raise DrivewmError("eval distribution: give --inception (FID) and/or --i3d (FVD), local TorchScript files")
    inception = InceptionFeatures(inception_path) if inception_path else None
    i3d = I3DFeatures(i3d_path) if i3d_path else None
    gen = collect_features(generated, inception, i3d, cfg, "generated")
    ref = collect_features(real, inception, i3d, cfg, "real")
    out: dict = {"config": dataclasses.asdict(cfg), "num_generated_clips": len(generated), "num_real_clips": len(real)}
    if inception is not None:
        out["fid"] = _figures(gen.fid, ref.fid, cfg)
    if i3d is not None:
        out["fvd"] = _figures(gen.fvd, ref.fvd, cfg)
        out["fvd_short_clips"] = {"generated": gen.short_clips, "real": ref.short_clips}
    return out


def markdown(metrics: dict) -> str:
    """One line per figure: value, interval and the sample counts beside it."""
    lines = ["# drivewm eval distribution", "", "| metric | view | value [interval] (samples) |", "|---|---|---|"]
    for name in ("fid", "fvd"):
        for view, fig in metrics.get(name, {}).items():
            text = fig.get("text") or f"n/a: {fig.get('error')}"
            lines.append(f"| {name.upper()} | {view} | {text} |")
    return "\n".join(lines) + "\n"


def write_distribution(out_dir: Path, metrics: dict) -> None:
    """distribution.json and distribution.md."""
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json(out_dir / "distribution.json", metrics)
    write_text(out_dir / "distribution.md", markdown(metrics))
