"""report.html: the futures side by side. A bird's-eye plot of every future's ego path and road users'
paths, one contact sheet per future (rows: cameras, columns: evenly spaced future frames), and the score
table best first. Pictures are PNG files beside the page (report/), referenced by relative paths."""

from __future__ import annotations

import html
from pathlib import Path

import cv2
import numpy as np

from drivewm.atomic import atomic_path, write_bytes, write_text
from drivewm.multiverse.branch import Branch

SHEET_COLUMNS = 5
SHEET_THUMB_WIDTH_PX = 192
COLUMNS = (
    ("collision", "collision"),
    ("min_ttc_s", "min TTC (s)"),
    ("min_gap_m", "min gap (m)"),
    ("progress_m", "progress (m)"),
    ("lane_offset_max_m", "max lane offset (m)"),
    ("off_road_fraction", "off road"),
    ("max_abs_jerk_mps3", "max |jerk| (m/s³)"),
    ("max_abs_lateral_accel_mps2", "max |lat. acc.| (m/s²)"),
)
VIDEO_COLUMNS = (
    ("cse", "CSE (px)"),
    ("tse", "TSE (px)"),
    ("adherence_weather", "weather ok"),
    ("adherence_time_of_day", "time ok"),
)


def sheet_frames(frames: dict[str, np.ndarray]) -> np.ndarray:
    """A contact sheet (uint8 RGB): one row per camera, :data:`SHEET_COLUMNS` evenly spaced frames."""
    rows = []
    for video in frames.values():
        idx = np.linspace(0, len(video) - 1, min(SHEET_COLUMNS, len(video))).round().astype(int)
        h, w = video.shape[1:3]
        size = (SHEET_THUMB_WIDTH_PX, max(1, round(h * SHEET_THUMB_WIDTH_PX / w)))
        rows.append(np.concatenate([cv2.resize(video[i], size, interpolation=cv2.INTER_AREA) for i in idx], axis=1))
    return np.concatenate(rows, axis=0)


def write_sheet(path: Path, sheet: np.ndarray) -> None:
    ok, png = cv2.imencode(".png", cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    write_bytes(path, png.tobytes())


def plot_birds_eye(path: Path, branch: Branch, ranking: dict) -> None:
    """Every future's ego path (coloured by plan) and its road users' paths (thin, same colour), the
    shared past in black, the road's lane centres in grey."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 6))
    ego = [t.T_world_from_ego[:2, 3] for f in branch.futures for t in f] + [
        t.T_world_from_ego[:2, 3] for t in branch.past
    ]
    lo, hi = np.min(ego, axis=0) - 40, np.max(ego, axis=0) + 40
    for c in branch.road.lane_centers:
        ax.plot(c[:, 0], c[:, 1], color="0.8", lw=0.8, zorder=0)
    colours = plt.get_cmap("tab10")
    rank_of = {f["plan"]: f["rank"] for f in ranking["futures"]}
    for i, (plan, future) in enumerate(zip(branch.plans, branch.futures)):
        col = colours(i % 10)
        for track in _tracks(future).values():
            ax.plot(track[:, 0], track[:, 1], color=col, lw=0.6, alpha=0.5)
        xy = np.stack([t.T_world_from_ego[:2, 3] for t in [branch.past[-1], *future]])
        ax.plot(xy[:, 0], xy[:, 1], color=col, lw=2.5, label=f"#{rank_of[plan.name]} {plan.name}")
        ax.plot(*xy[-1], "o", color=col)
    past = np.stack([t.T_world_from_ego[:2, 3] for t in branch.past])
    ax.plot(past[:, 0], past[:, 1], color="k", lw=2.5, label="past")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="best", fontsize=8)
    ax.set_title("futures: ego (thick) and road users (thin)")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=90, metadata={"Software": None})
    plt.close(fig)


def _tracks(future) -> dict[str, np.ndarray]:
    tracks: dict[str, list] = {}
    for t in future:
        for a in t.agents:
            tracks.setdefault(a.track_id, []).append(np.asarray(a.center_xyz[:2]))
    return {k: np.stack(v) for k, v in tracks.items()}


def _cell(value) -> str:
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.2f}"
    return html.escape(str(value))


def _row(f: dict) -> str:
    s, v = f["scores"], f["scores"].get("video", {})
    who = s.get("collision_with")
    collision = f"yes ({who['category']} {who['track_id']} at {who['time_s']:.1f} s)" if who else "no"
    feasible = "yes" if f.get("feasible", True) else f"no: {f['infeasible']}"
    cells = (
        [f["rank"], f["plan"], feasible, collision]
        + [s.get(k) for k, _ in COLUMNS[1:]]
        + [v.get(k) for k, _ in VIDEO_COLUMNS]
    )
    return "<tr>" + "".join(f"<td>{_cell(c)}</td>" for c in cells) + "</tr>"


def _sheet(f: dict) -> str:
    name = html.escape(f["plan"])
    return f'<h3>#{f["rank"]} {name}</h3><img src="report/{name}.png" alt="{name} cameras">'


def _sampling(sampling: dict | None) -> str:
    """The model's sampler settings in a few words, e.g. ", 10 heun steps a window, guidance 7"."""
    if not sampling:
        return ""
    return f", {sampling['steps']} {html.escape(sampling['sampler'])} steps a window, guidance {sampling['guidance']:g}"


def render_html(ranking: dict) -> str:
    """The page: what was branched and rendered how, the plot, the score table best first, the sheets."""
    head = "".join(f"<th>{html.escape(t)}</th>" for _, t in COLUMNS + VIDEO_COLUMNS)
    users = "reactive road users" if ranking["reactive"] else "road users replayed from the log"
    cams = ", ".join(html.escape(c) for c in ranking["cameras"])
    renderer = html.escape(ranking["renderer_description"])
    model = (
        f" (model {html.escape(ranking['model'])}{_sampling(ranking['model_sampling'])})" if ranking["model"] else ""
    )
    return f"""<!doctype html>
<html><head><meta charset="utf-8"><title>drivewm multiverse</title>
<style>body{{font-family:sans-serif;margin:1.5em}} table{{border-collapse:collapse}}
td,th{{border:1px solid #bbb;padding:3px 7px;text-align:right}} td:nth-child(2){{text-align:left}}
img{{max-width:100%}}</style></head><body>
<h1>Multiverse: {len(ranking["futures"])} futures</h1>
<p>Source: {html.escape(ranking["source"])} ({users}), branch at {ranking["branch_time_s"]:.2f} s,
horizon {ranking["horizon_s"]:.2f} s. Cameras rendered by: <b>{renderer}</b>{model}.</p>
<p>Ranking rule: {html.escape(ranking["rule"]["description"])}</p>
<h2>Bird's-eye view</h2><img src="report/birds_eye.png" alt="bird's-eye view of all futures">
<h2>Scores, best first</h2>
<table><tr><th>rank</th><th>plan</th><th>feasible</th>{head}</tr>
{"".join(_row(f) for f in ranking["futures"])}
</table>
<h2>Cameras per future</h2><p>Rows: {cams}; columns: evenly spaced frames after the branch point.</p>
{"".join(_sheet(f) for f in ranking["futures"])}
</body></html>
"""


def write_report(folder: Path, branch: Branch, ranking: dict, sheets: dict[str, np.ndarray]) -> None:
    """report.html with report/birds_eye.png and report/PLAN.png."""
    (folder / "report").mkdir(parents=True, exist_ok=True)
    plot_birds_eye(folder / "report" / "birds_eye.png", branch, ranking)
    for plan, sheet in sheets.items():
        write_sheet(folder / "report" / f"{plan}.png", sheet)
    write_text(folder / "report.html", render_html(ranking))
