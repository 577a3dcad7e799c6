"""``drivewm eval compare RUN_A RUN_B ...``: several eval outputs side by side in one HTML page.

Each RUN is an ``eval`` output folder (metrics.json; trajectories.json and an ``eval distribution``'s
distribution.json when present). The page shows:

- every aggregate figure per run with a 95% bootstrap interval over the run's clips and the number
  of clips it rests on (FID / FVD with their own intervals and sample counts);
- per run the worst camera pairs (CSE) and frame pairs (TSE), with their matches drawn when the
  run's recorded input (metrics.json ``input``) can still be read: the frames are decoded again and
  matched with the run's own matcher, verified matches green, the rest red;
- per run the recovered ego paths against the conditioned (and logged) ones (trajectories.json).

Written atomically to ``DIR/compare.html`` with its pictures under ``DIR/compare_files/``.
"""

from __future__ import annotations

import dataclasses
import html
import math
from pathlib import Path

import numpy as np

from drivewm.atomic import atomic_path, write_json, write_text
from drivewm.errors import DrivewmError
from drivewm.eval.report import TABLE_ROWS, read_json_object

WORST_PAIRS = 3
"""Camera pairs and frame pairs shown per run."""
BOOTSTRAP = 1000
"""Bootstrap resamples of each interval over clips."""
PATHS_PER_RUN = 4
"""Clips whose ego paths are plotted per run."""
LINES_DRAWN = 150
"""Matches drawn per picture at most (evenly spread over them; the counts are of all)."""
MEDIAN_SUFFIX = "_median"
"""Aggregates that are medians over clips (drivewm.eval.suite.MEDIAN_KEYS) end so."""


@dataclasses.dataclass
class Run:
    """One eval output folder."""

    name: str
    folder: Path
    metrics: dict
    distribution: dict | None
    trajectories: dict | None


def load_run(folder: str | Path, name: str) -> Run:
    """An eval output folder; metrics.json is required, the others optional."""
    folder = Path(folder)
    if not (folder / "metrics.json").is_file():
        raise DrivewmError(f"{folder}: not an eval output (no metrics.json)")
    metrics = read_json_object(folder / "metrics.json", "eval metrics")
    if not isinstance(metrics.get("clips"), dict):
        raise DrivewmError(f"{folder / 'metrics.json'}: no per-clip metrics ('clips')")
    optional = {f: folder / f for f in ("distribution.json", "trajectories.json")}
    dist, traj = (read_json_object(p, f) if p.is_file() else None for f, p in optional.items())
    return Run(name, folder, metrics, dist, traj)


def clip_interval(values: list, bootstrap: int = BOOTSTRAP, seed: int = 0, median=False) -> tuple[float, float, int]:
    """95% percentile-bootstrap interval of the mean (or ``median``) over clips, and the number of clips
    with a value."""
    v = np.array([x for x in values if isinstance(x, (int, float)) and math.isfinite(x)], dtype=np.float64)
    if len(v) == 0:
        return math.nan, math.nan, 0
    rng = np.random.default_rng(seed)
    stat = np.median if median else np.mean
    means = stat(v[rng.integers(0, len(v), (bootstrap, len(v)))], axis=1)
    low, high = np.percentile(means, [2.5, 97.5])
    return float(low), float(high), len(v)


def figure_rows(runs: list[Run]) -> list[dict]:
    """Per aggregate key any run has: per run the value, its interval over clips and its clip count."""
    rows = []
    for key, unit, meaning in TABLE_ROWS:
        if not any(key in r.metrics for r in runs):
            continue
        cells = []
        median = key.endswith(MEDIAN_SUFFIX)  # e.g. path_ratio_median: the median of the clips' path_ratio
        clip_key = key[: -len(MEDIAN_SUFFIX)] if median else key
        for r in runs:
            low, high, n = clip_interval([c.get(clip_key) for c in r.metrics["clips"].values()], median=median)
            cells.append({"value": r.metrics.get(key), "low": low, "high": high, "n": n, "unit": "clips"})
        rows.append({"key": key, "unit": unit, "meaning": meaning, "cells": cells})
    for name in ("fid", "fvd"):
        for view in sorted({v for r in runs for v in ((r.distribution or {}).get(name) or {})}):
            cells = []
            for r in runs:
                fig = ((r.distribution or {}).get(name) or {}).get(view, {})
                cells.append(
                    {
                        "value": fig.get("value"),
                        "low": fig.get("low", math.nan),
                        "high": fig.get("high", math.nan),
                        "n": fig.get("num_generated", 0),
                        "unit": f"generated, {fig.get('num_real', 0)} real",
                    }
                )
            rows.append({"key": f"{name}_{view}", "unit": "", "meaning": f"{name.upper()} of {view}", "cells": cells})
    return rows


def worst_camera_pairs(metrics: dict, k: int = WORST_PAIRS) -> list[dict]:
    """The ``k`` CSE camera pairs of highest median Sampson error (px) over all clips."""
    found = []
    for key, clip in metrics["clips"].items():
        for pair, med in zip(clip.get("cse_pairs", []), clip.get("cse_pair_medians", [])):
            if med is not None and math.isfinite(med):
                a, b = pair.split("~")
                label = f"{pair} (frame 0 shown)"
                found.append({"clip": key, "a": (a, 0), "b": (b, 0), "label": label, "median_px": med})
    return sorted(found, key=lambda f: -f["median_px"])[:k]


def worst_frame_pairs(metrics: dict, k: int = WORST_PAIRS) -> list[dict]:
    """The ``k`` TSE frame pairs (camera, t, t + gap) of highest median Sampson error (px) over all clips.
    A clip's ``tse_pair_medians`` run camera by camera (rig order), frame by frame."""
    gap = int(metrics.get("config", {}).get("consistency", {}).get("frame_gap", 1))
    found = []
    for key, clip in metrics["clips"].items():
        cameras, medians = list(clip.get("native_px_per_canonical_px", {})), clip.get("tse_pair_medians", [])
        if not cameras or len(medians) % len(cameras):
            continue
        per_camera = len(medians) // len(cameras)
        for i, med in enumerate(medians):
            if med is not None and math.isfinite(med):
                cam, t = cameras[i // per_camera], i % per_camera
                label = f"{cam} frames {t}-{t + gap}"
                found.append({"clip": key, "a": (cam, t), "b": (cam, t + gap), "label": label, "median_px": med})
    return sorted(found, key=lambda f: -f["median_px"])[:k]


def _items_by_key(run: Run) -> tuple[dict, str]:
    """The run's clips read again from its recorded input, by key; or an empty dict and why not."""
    from drivewm.eval.framing import framing_from_record
    from drivewm.eval.inputs import load_items
    from drivewm.geometry import rig_from_dict

    record = run.metrics.get("input")
    if not record:
        return {}, "this eval output records no input (metrics.json 'input'): matches not drawn"
    rig = record.get("rig")
    rig = rig_from_dict(rig, "recorded rig") if isinstance(rig, dict) else rig
    try:
        items = load_items(
            record["location"],
            rig,
            record.get("grid"),
            record.get("cameras"),
            record.get("rig_fit", "same"),
            framing_from_record(record.get("framing") or {}),
        )
    except DrivewmError as exc:
        return {}, f"input not readable ({exc}): matches not drawn"
    return {i.key: i for i in items}, ""


def draw_matches(image_a: np.ndarray, image_b: np.ndarray, match_cfg) -> tuple[np.ndarray, int, int]:
    """Both images side by side with their matches: green where a robust F (OpenCV MAGSAC, 1 px) keeps
    them, red where not. Returns the RGB picture, the verified and the total match counts."""
    import cv2

    from drivewm.eval.matching import FrameMatcher

    m = FrameMatcher(match_cfg).match("a", image_a, "b", image_b)
    inliers = np.zeros(len(m), bool)
    if len(m) >= 8:
        _, mask = cv2.findFundamentalMat(m.uv_a, m.uv_b, cv2.USAC_MAGSAC, 1.0, 0.999, 10000)
        inliers = mask.ravel().astype(bool) if mask is not None else inliers
    h = max(image_a.shape[0], image_b.shape[0])
    canvas = np.zeros((h, image_a.shape[1] + image_b.shape[1], 3), np.uint8)
    canvas[: image_a.shape[0], : image_a.shape[1]] = image_a
    canvas[: image_b.shape[0], image_a.shape[1] :] = image_b
    shown = np.unique(np.linspace(0, len(m) - 1, min(len(m), LINES_DRAWN)).astype(int))
    for (ua, va), (ub, vb), ok in zip(m.uv_a[shown], m.uv_b[shown], inliers[shown]):
        colour = (0, 220, 90) if ok else (230, 40, 40)
        cv2.line(canvas, (int(ua), int(va)), (int(ub) + image_a.shape[1], int(vb)), colour, 1, cv2.LINE_AA)
    return canvas, int(inliers.sum()), len(m)


def _save_png(path: Path, rgb: np.ndarray) -> None:
    import cv2

    ok, data = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    if not ok:
        raise DrivewmError(f"{path}: cannot encode PNG")
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(data.tobytes())


def pair_pictures(run: Run, pairs: list[dict], files: Path, prefix: str) -> str:
    """Draw each pair's matches under ``files``; sets ``picture`` (file name) and ``matches`` on each pair.
    Returns a note when they could not be drawn."""
    from drivewm.eval.config import MatchConfig

    items, note = _items_by_key(run)
    if not items:
        return note
    match_cfg = MatchConfig(**run.metrics.get("config", {}).get("match", {}))
    videos_of: dict[str, dict] = {}
    for i, p in enumerate(pairs):
        item = items.get(p["clip"])
        if item is None:
            continue
        if p["clip"] not in videos_of:
            videos_of[p["clip"]] = item.videos()
        videos = videos_of[p["clip"]]
        (ca, ta), (cb, tb) = p["a"], p["b"]
        picture, verified, total = draw_matches(videos[ca][ta], videos[cb][tb], match_cfg)
        p["picture"], p["matches"] = f"{prefix}_{i}.png", f"{verified} of {total} verified"
        _save_png(files / p["picture"], picture)
    return ""


def plot_paths(run: Run, path: Path) -> bool:
    """Recovered ego paths (scaled by least squares onto the conditioned or logged path: monocular scale)
    against the conditioned waypoints and the logged path, top view. False when the run has no paths."""
    clips = [(k, t) for k, t in (run.trajectories or {}).items() if t.get("recovered")][:PATHS_PER_RUN]
    if not clips:
        return False
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(clips), figsize=(4 * len(clips), 4), squeeze=False)
    for ax, (key, t) in zip(axes[0], clips):
        _plot_clip_paths(ax, t)
        ax.set_title(key, fontsize=8)
        ax.set_xlabel("x forward (m)")
        ax.set_ylabel("y left (m)")
        ax.axis("equal")
        ax.legend(fontsize=7)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=80)
    plt.close(fig)
    return True


def _plot_clip_paths(ax, t: dict) -> None:
    rec = np.asarray(t["recovered"], dtype=np.float64)
    target = None
    if t.get("conditioned"):
        way = np.asarray(t["conditioned"], dtype=np.float64)
        ax.plot(way[:, 0], way[:, 1], "o--", ms=3, color="tab:orange", label="conditioned")
        way_t = (np.arange(len(way)) + 1) * t["conditioned_dt_s"]
        frame_t = np.asarray(t["recovered_frames"]) / t["fps"]
        keep = way_t <= frame_t[-1]
        if keep.any():
            target = (np.stack([np.interp(way_t[keep], frame_t, rec[:, i]) for i in range(3)], 1), way[keep])
    if t.get("reference"):
        ref = np.asarray(t["reference"], dtype=np.float64)
        ax.plot(ref[:, 0], ref[:, 1], "-", color="tab:gray", label="logged")
        target = target or (rec, ref[t["recovered_frames"]])
    scale = 1.0
    if target is not None:
        q, w = target
        denom = float(np.sum(q * q))
        scale = float(np.sum(q * w)) / denom if denom > 0 else 1.0
    ax.plot(scale * rec[:, 0], scale * rec[:, 1], "-", color="tab:blue", label=f"recovered (x{scale:.2g})")


#: Counts the pictures a browser decoded into ``body[data-figures-loaded]`` (the browser check reads it).
LOADED_SCRIPT = (
    "window.addEventListener('load', () => { document.body.dataset.figuresLoaded = "
    "[...document.images].filter(i => i.complete && i.naturalWidth > 0).length; });"
)


def _cell(c: dict) -> str:
    v = c["value"]
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return f"n/a <small>(n={c['n']})</small>"
    interval = "" if not math.isfinite(c["low"]) else f" [{c['low']:.3g}, {c['high']:.3g}]"
    return f"{v:.3g}{interval} <small>(n={c['n']} {html.escape(c['unit'])})</small>"


def render_html(runs: list[Run], rows: list[dict], sections: list[str]) -> str:
    """The page: the figure table, then one section per run."""
    head = "".join(f"<th>{html.escape(r.name)}</th>" for r in runs)
    body = "".join(
        f"<tr><td title='{html.escape(row['meaning'])}'>{html.escape(row['key'])}</td>"
        f"<td>{html.escape(row['unit'])}</td>" + "".join(f"<td>{_cell(c)}</td>" for c in row["cells"]) + "</tr>"
        for row in rows
    )
    style = (
        "body{font-family:sans-serif;margin:1.5em}table{border-collapse:collapse}"
        "td,th{border:1px solid #bbb;padding:3px 8px;font-size:13px}img{max-width:100%;border:1px solid #ccc}"
    )
    pictures = sum(section.count("<img") for section in sections)
    return (
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>drivewm eval compare</title>"
        f"<style>{style}</style></head><body data-figures='{pictures}' data-figures-loaded='0'>"
        "<h1>drivewm eval compare</h1>"
        "<p>Each figure: the run's aggregate, a 95% bootstrap interval of the mean over its clips, and the "
        "number of clips (FID / FVD: generated and real samples) it rests on.</p>"
        f"<table id='figures'><tr><th>metric</th><th>unit</th>{head}</tr>{body}</table>{''.join(sections)}"
        f"<script>{LOADED_SCRIPT}</script></body></html>\n"
    )


def _pairs_html(title: str, pairs: list[dict], note: str, files_name: str) -> str:
    parts = [f"<h3>{html.escape(title)}</h3>"]
    if note:
        parts.append(f"<p><i>{html.escape(note)}</i></p>")
    for p in pairs:
        line = f"{p['clip']}: {p['label']}: median {p['median_px']:.3g} px"
        if p.get("matches"):
            line += f", {p['matches']}"
        parts.append(f"<p>{html.escape(line)}</p>")
        if p.get("picture"):
            parts.append(f"<img src='{files_name}/{p['picture']}' alt='{html.escape(p['label'])}'>")
    return "".join(parts)


def run_section(run: Run, index: int, files: Path, pictures: bool) -> tuple[str, dict]:
    """One run's worst pairs and paths as HTML, and the same as JSON."""
    cams, frames = worst_camera_pairs(run.metrics), worst_frame_pairs(run.metrics)
    note_c = note_f = "pictures skipped (--no-pictures)"
    has_paths = False
    if pictures:
        note_c = pair_pictures(run, cams, files, f"run{index}_camera_pair")
        note_f = pair_pictures(run, frames, files, f"run{index}_frame_pair")
        has_paths = plot_paths(run, files / f"run{index}_paths.png")
    parts = [f"<h2>{html.escape(run.name)}</h2><p>{html.escape(str(run.folder))}</p>"]
    parts.append(_pairs_html("Worst camera pairs (CSE)", cams, note_c, files.name))
    parts.append(_pairs_html("Worst frame pairs (TSE)", frames, note_f, files.name))
    parts.append("<h3>Ego paths</h3>")
    if has_paths:
        parts.append(f"<img src='{files.name}/run{index}_paths.png' alt='ego paths'>")
    else:
        parts.append("<p><i>no recovered ego path in this run (trajectories.json)</i></p>")
    return "".join(parts), {"worst_camera_pairs": cams, "worst_frame_pairs": frames}


def _run_names(folders: list[str]) -> list[str]:
    names = [Path(f).resolve().name or str(f) for f in folders]
    return [n if names.count(n) == 1 else f"{n} ({i + 1})" for i, n in enumerate(names)]


def compare_runs(folders: list[str], out_dir: str | Path, pictures: bool = True) -> Path:
    """compare.html (and compare.json) of the eval outputs ``folders`` under ``out_dir``."""
    if len(folders) < 1:
        raise DrivewmError("eval compare: give at least one eval output folder")
    runs = [load_run(f, n) for f, n in zip(folders, _run_names(folders))]
    out_dir = Path(out_dir)
    files = out_dir / "compare_files"
    files.mkdir(parents=True, exist_ok=True)
    rows = figure_rows(runs)
    sections, details = [], {}
    for i, run in enumerate(runs):
        section, detail = run_section(run, i, files, pictures)
        sections.append(section)
        details[run.name] = detail
    write_json(
        out_dir / "compare.json", {"runs": [str(r.folder) for r in runs], "figures": rows, "runs_detail": details}
    )
    page = out_dir / "compare.html"
    write_text(page, render_html(runs, rows, sections))
    return page
