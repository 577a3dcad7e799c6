"""The benchmark's outputs: metrics.json, a Markdown table beside reference values, plots, Rerun.

``metrics.json``: aggregates at the top level (tse, cse, pose_success, ate, rpe_trans, rpe_rot, tfe,
...), per clip under ``clips``, the resolved protocol under ``config``. ``metrics.md``: one row per
aggregate with the reference ("real") value beside it when a reference JSON is given (same keys;
a path, or the name of a packaged one in drivewm/references/). ``error_distributions.png``: per-pair
TSE / CSE medians and per-clip trajectory errors. ``eval.rrd``: per clip, the first CSE pair's
matches and the recovered vs reference trajectory.
matplotlib and Rerun (seconds to import) load only when the pictures are drawn.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from drivewm import resources
from drivewm.atomic import atomic_path, write_json, write_text
from drivewm.errors import DrivewmError

#: (key, unit, description) rows of the Markdown table, in order.
TABLE_ROWS = (
    ("tse", "px", "temporal Sampson error, F fitted per frame pair; failed pairs at 4 px (lower is better)"),
    ("tse_calibrated", "px", "temporal Sampson error under the F of the logged ego motion"),
    ("tse_native", "px", "TSE in the cameras' own pixels"),
    ("tse_counted", "px", "TSE over the pairs that count only (the Cosmos paper's figure)"),
    ("tse_counted_fraction", "rate", "TSE frame pairs with enough verified matches and motion"),
    ("tse_matches", "count", "verified matches per TSE frame pair"),
    ("cse", "px", "cross-view Sampson error, one F fitted per camera pair over all frames"),
    ("cse_calibrated", "px", "cross-view Sampson error under the rig's calibrated F"),
    ("cse_native", "px", "CSE in the cameras' own pixels"),
    ("cse_counted", "px", "CSE over the pairs that count only (the Cosmos paper's figure)"),
    ("cse_counted_fraction", "rate", "CSE camera pairs with enough distinct verified matches"),
    ("cse_matches", "count", "distinct verified matches per CSE camera pair (all frames)"),
    (
        "overlap_disagreement",
        "levels",
        "colour difference where two cameras see one flat-world point (real clips ~8, stitched views ~2)",
    ),
    ("pose_success", "rate", "clips whose frames all register in COLMAP (higher is better)"),
    ("pose_success_path", "rate", "clips that register and travel their own ego path (m, within 2x; higher is better)"),
    ("path_ratio_median", "ratio", "median over clips: recovered ego path length over the clip's own (1: on it)"),
    ("registered_fraction", "rate", "frames registered by COLMAP"),
    ("pose_auc", "rate", "per-image pose accuracy against the reference, area up to 0.25 m / 2 deg (higher is better)"),
    ("pose_error_m", "m", "median per-image position error after aligning all camera centres"),
    ("pose_error_deg", "deg", "median per-image rotation error after aligning all camera centres"),
    ("ate", "m", "absolute trajectory error after Sim(3) alignment"),
    ("rpe_trans", "m", "relative pose error, translation per frame step (RMSE)"),
    ("rpe_rot", "deg", "relative pose error, rotation per frame step (mean)"),
    ("rpe_trans_mean", "m", "relative pose error, translation (mean)"),
    ("rpe_rot_rmse", "deg", "relative pose error, rotation (RMSE, as evo reports it)"),
    ("tfe", "m", "trajectory-following error against the conditioned waypoints"),
    ("adherence_weather", "rate", "clips classified as the prompted weather"),
    ("adherence_time_of_day", "rate", "clips classified as the prompted time of day"),
)


def load_reference(path: str | Path | None) -> dict:
    """A reference metrics JSON (a metrics.json, or {"name": ..., "metrics": {key: value}}): a path, or
    the name of a packaged reference (``cosmos_paper``, ``sim_clips``)."""
    if path is None:
        return {}
    path = resources.find("references", path, "reference metrics", suffix=".json")
    data = read_json_object(path, "reference metrics")
    return {"name": data.get("name", path.stem), "metrics": data.get("metrics", data)}


def read_json_object(path: Path, what: str) -> dict:
    """A JSON object from ``path``; an unreadable file or another JSON value is one DrivewmError naming ``what``."""
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise DrivewmError(f"{path}: cannot read {what} ({exc.__class__.__name__})") from None
    if not isinstance(data, dict):
        raise DrivewmError(f"{path}: {what} must be a JSON object")
    return data


def _fmt(v) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    return f"{v:.3f}" if isinstance(v, (int, float)) else str(v)


def markdown_table(metrics: dict, reference: dict) -> str:
    """The aggregate metrics beside the reference values, one row per metric."""
    ref_name = reference.get("name", "reference")
    ref = reference.get("metrics", {})
    lines = [
        f"# drivewm eval: {metrics.get('location', '')}",
        "",
        f"{metrics.get('num_clips', 0)} clips ({metrics.get('num_failed_clips', 0)} unreadable).",
        "",
        f"| metric | evaluated | {ref_name} | unit | clips without a value | meaning |",
        "|---|---|---|---|---|---|",
    ]
    for key, unit, text in TABLE_ROWS:
        if key in metrics:
            nan = metrics.get("nan_clips", {}).get(key, 0)
            lines.append(f"| {key} | {_fmt(metrics[key])} | {_fmt(ref.get(key))} | {unit} | {nan} | {text} |")
    return "\n".join(lines) + "\n"


def plot_distributions(path: Path, metrics: dict) -> None:
    """Histograms of per-pair TSE / CSE medians and per-clip trajectory errors."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    clips = list(metrics["clips"].values())

    def values(key: str) -> list[float]:
        out = []
        for c in clips:
            v = c.get(key)
            out += v if isinstance(v, list) else [v]
        return [x for x in out if x is not None and np.isfinite(x)]

    panels = [
        ("TSE pair medians (px)", "tse_pair_medians", "tse_calibrated_pair_medians"),
        ("CSE pair medians (px)", "cse_pair_medians", "cse_calibrated_pair_medians"),
        ("ATE per clip (m)", "ate", None),
        ("TFE per clip (m)", "tfe", None),
    ]
    fig, axes = plt.subplots(1, 4, figsize=(16, 3.4))
    for ax, (title, key, cal_key) in zip(axes, panels):
        fitted = values(key)
        ax.hist(fitted, bins=20, alpha=0.7, label="fitted F" if cal_key else None)
        if cal_key and values(cal_key):
            ax.hist(values(cal_key), bins=20, alpha=0.6, label="calibrated F")
            ax.legend()
        ax.set_title(f"{title}  (n={len(fitted)})")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=90)
    plt.close(fig)


def write_rerun(path: Path, results: list) -> None:
    """Matches of the first CSE pair (frame 0) and recovered vs reference trajectories per clip."""
    import rerun as rr

    with atomic_path(path) as tmp:
        rec = rr.RecordingStream("drivewm_eval", recording_id="eval")
        rec.save(str(tmp))
        for r in results:
            _log_clip(rec, rr, r)
        rec.flush()
        rec.disconnect()


def _log_clip(rec, rr, result) -> None:
    base = f"clips/{result.key}"
    m = result.artifacts.get("cse_matches")
    if m is not None:
        img_a, img_b = m["images"]
        rec.log(f"{base}/matches/image", rr.Image(np.concatenate([img_a, img_b], axis=1)), static=True)
        shift = np.array([img_a.shape[1], 0.0])
        strips = [np.stack([a, b + shift]) for a, b in zip(m["uv_a"], m["uv_b"])]
        rec.log(f"{base}/matches/lines", rr.LineStrips2D(strips, colors=[[0, 255, 120]]), static=True)
    traj = result.artifacts.get("trajectory")
    if traj is not None:
        rec.log(
            f"{base}/trajectory/reference", rr.LineStrips3D([traj["reference"]], colors=[[255, 200, 0]]), static=True
        )
        rec.log(
            f"{base}/trajectory/recovered", rr.LineStrips3D([traj["recovered"]], colors=[[0, 160, 255]]), static=True
        )


def write_report(
    out_dir: Path, metrics: dict, results: list, reference: str | Path | None, pictures: bool = True
) -> None:
    """metrics.json (NaN written as null), metrics.md, trajectories.json (per clip: recovered, logged and
    conditioned ego paths; drivewm.eval.paths_record), error_distributions.png and eval.rrd."""
    ref = load_reference(reference)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json(out_dir / "metrics.json", metrics)
    write_text(out_dir / "metrics.md", markdown_table(metrics, ref))
    paths = {r.key: r.artifacts["ego_paths"] for r in results if "ego_paths" in r.artifacts}
    if paths:
        write_json(out_dir / "trajectories.json", paths)
    if pictures:
        plot_distributions(out_dir / "error_distributions.png", metrics)
        write_rerun(out_dir / "eval.rrd", results)
