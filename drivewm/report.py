"""The quickstart report: one HTML page and its Markdown twin over a pipeline output folder.

It reads only the files the stages wrote (curation report.json, tokenizer metrics.json, training
metrics.jsonl, eval metrics.json, contact sheets), so it can be rebuilt at any time. Figures are
linked relatively; the page counts its own loaded figures on ``load`` (``data-figures-loaded``),
which the browser test reads.
"""

from __future__ import annotations

import html
import json
from collections import Counter
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from drivewm.atomic import atomic_path, read_jsonl, write_text  # noqa: E402

#: Eval metrics shown in the real-vs-generated table, with their meaning and unit.
EVAL_ROWS = {
    "tse": "temporal Sampson error (px, lower is better)",
    "cse": "cross-view Sampson error (px, lower is better)",
    "pose_success": "pose-estimation success (fraction of clips)",
    "ate": "absolute trajectory error (m)",
    "rpe_trans": "relative pose error, translation (m)",
    "rpe_rot": "relative pose error, rotation (deg)",
    "tfe": "trajectory-following error (m)",
}


def _read_json(path: Path) -> dict:
    return json.loads(path.read_text()) if path.is_file() else {}


def _fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:.3f}"
    return "n/a" if value is None else str(value)


def training_curves(out: Path, dest: Path) -> Path | None:
    """Plot loss against step for every stage that wrote metrics.jsonl; None if there are none."""
    names = ("tokenizer", "text2world", "multiview", "transfer_model")
    runs = {name: read_jsonl(out / name / "metrics.jsonl") for name in names}
    runs = {k: v for k, v in runs.items() if v}
    if not runs:
        return None
    fig, axes = plt.subplots(1, len(runs), figsize=(4.2 * len(runs), 3.2), squeeze=False)
    for ax, (name, rows) in zip(axes[0], runs.items()):
        ax.plot([r["step"] for r in rows], [r["loss"] for r in rows])
        ax.set(title=name, xlabel="step", ylabel="training loss", yscale="log")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(dest) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return dest


def gather(out: Path, rig: str, generations: list[str]) -> dict:
    """Every number and figure the report shows, from the stage outputs in ``out``."""
    curate = _read_json(out / "clips" / "report.json")
    figures = {"Simulated clips (curated, all views)": out / "clips" / "contact_sheet.png"}
    for first in sorted((out / "tokenizer_eval").glob("*.png"))[:1]:
        figures["Tokenizer reconstruction (input | output)"] = first
    curves = training_curves(out, out / "training_curves.png")
    if curves:
        figures["Training curves"] = curves
    for name in generations:
        figures[f"Generated: {name}"] = out / "generated" / name / "contact_sheet.png"
    transferred = _read_json(out / "transfer" / "report.json")
    if transferred.get("written"):
        what = f"Transferred: {transferred['written'][0]} (source above, transferred below, all views)"
        figures[what] = out / "transfer" / "contact_sheet.png"
    return {
        "rig": rig,
        "curate": curate,
        "tokenizer": _read_json(out / "tokenizer_eval" / "metrics.json"),
        "eval": {name: _read_json(out / "eval" / name / "metrics.json") for name in ["real", *generations]},
        "figures": {k: v for k, v in figures.items() if v.is_file()},
        "recording": out / "drive.rrd",
    }


#: The per-clip status entry that says why a metric has no value (eval's metrics.json).
STATUS_OF = {"tse": "tse", "cse": "cse", "ate": "traj", "rpe_trans": "traj", "rpe_rot": "traj", "tfe": "traj"}


def _missing_reason(metrics: dict, key: str) -> str:
    """Why ``key`` has no aggregate: the most common per-clip status, e.g. 'too_few_matches'."""
    reasons: Counter = Counter()
    for clip in (metrics.get("clips") or {}).values():
        status = (clip.get("status") or {}).get(STATUS_OF.get(key, key))
        if isinstance(status, dict):
            reasons.update({r: n for r, n in status.items() if r != "ok"})
        elif status and status != "ok":
            reasons[status] += 1
    return reasons.most_common(1)[0][0] if reasons else "not measured"


def _cell(metrics: dict, key: str) -> str:
    """A table cell: the value, or 'n/a (reason)' naming why eval could not measure it."""
    if metrics.get(key) is not None:
        return _fmt(metrics[key])
    return f"n/a ({_missing_reason(metrics, key)})" if metrics else "n/a"


def _eval_table(facts: dict) -> tuple[list[str], list[list[str]]]:
    """Header (metric, meaning, one column per evaluated set) and rows for the metrics present."""
    sets = facts["eval"]
    header = [
        "metric",
        "meaning",
        *[
            (f"real clips ({m.get('num_clips', 0)})" if n == "real" else f"generated: {n} ({m.get('num_clips', 0)})")
            for n, m in sets.items()
        ],
    ]
    rows = [
        [k, EVAL_ROWS[k], *[_cell(m, k) for m in sets.values()]]
        for k in EVAL_ROWS
        if any(k in m for m in sets.values())
    ]
    return header, rows


def _curate_line(curate: dict) -> str:
    kept = curate.get("kept", curate.get("clips_kept", "n/a"))
    dropped = curate.get("dropped", {})
    if isinstance(dropped, dict):
        dropped = ", ".join(f"{r}: {n}" for r, n in sorted(dropped.items())) or "none"
    return f"clips kept: {kept}; dropped by reason: {dropped}"


def to_markdown(facts: dict, stages: list[tuple[str, list[str]]], out: Path) -> str:
    tok = facts["tokenizer"]
    lines = [
        "# drivewm quickstart report",
        "",
        f"Rig: `{facts['rig']}`",
        "",
        "## Curation",
        "",
        _curate_line(facts["curate"]),
        "",
        "## Tokenizer",
        "",
        f"PSNR {_fmt(tok.get('psnr'))} dB, SSIM {_fmt(tok.get('ssim'))} on held-out clips",
        "",
        "## Consistency benchmark: real vs generated",
        "",
    ]
    header, rows = _eval_table(facts)
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join([f"`{r[0]}`", *r[1:]]) + " |" for r in rows]
    lines += ["", "## Figures", ""]
    lines += [f"### {title}\n\n![{title}]({path.relative_to(out)})\n" for title, path in facts["figures"].items()]
    lines += (
        [
            "## Rerun recording",
            "",
            f"`{facts['recording']}` (open with `rerun {facts['recording'].name}`)",
            "",
            "## Commands run",
            "",
            "```",
        ]
        + [f"drivewm {' '.join(argv)}" for _, argv in stages]
        + ["```", ""]
    )
    return "\n".join(lines)


def to_html(facts: dict, stages: list[tuple[str, list[str]]], out: Path) -> str:
    e = html.escape
    tok = facts["tokenizer"]
    header, table = _eval_table(facts)
    head = "".join(f"<th>{e(h)}</th>" for h in header)
    rows = "".join(
        "<tr><td><code>" + e(r[0]) + "</code></td>" + "".join(f"<td>{e(c)}</td>" for c in r[1:]) + "</tr>"
        for r in table
    )
    figs = "".join(
        f"<figure><img src='{e(str(p.relative_to(out)))}' alt='{e(t)}'><figcaption>{e(t)}</figcaption></figure>"
        for t, p in facts["figures"].items()
    )
    cmds = e("\n".join(f"drivewm {' '.join(argv)}" for _, argv in stages))
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>drivewm quickstart report</title>
<style>body{{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}}
table{{border-collapse:collapse}}td,th{{border:1px solid #ccc;padding:4px 10px;text-align:left}}
figure{{margin:1.5em 0}}img{{max-width:100%;border:1px solid #ddd}}
pre{{background:#f6f6f6;padding:1em;overflow:auto}}</style></head>
<body data-figures="{len(facts["figures"])}">
<h1>drivewm quickstart report</h1>
<p>Rig <code>{e(facts["rig"])}</code>. <span id="figure-status">loading figures...</span></p>
<h2>Curation</h2><p>{e(_curate_line(facts["curate"]))}</p>
<h2>Tokenizer</h2><p>PSNR {e(_fmt(tok.get("psnr")))} dB, SSIM {e(_fmt(tok.get("ssim")))} on held-out clips.</p>
<h2>Consistency benchmark: real vs generated</h2>
<table id="eval-table"><tr>{head}</tr>{rows}</table>
<h2>Figures</h2>{figs}
<h2>Rerun recording</h2><p><code>{e(str(facts["recording"]))}</code> (open with <code>rerun</code>)</p>
<h2>Commands run</h2><pre>{cmds}</pre>
<script>
window.addEventListener("load", () => {{
  const imgs = [...document.images];
  const ok = imgs.filter(i => i.complete && i.naturalWidth > 0).length;
  document.body.dataset.figuresLoaded = ok;
  document.getElementById("figure-status").textContent = ok + " of " + imgs.length + " figures loaded";
}});
</script>
</body></html>
"""


def write_report(out: Path, rig: str, generations: list[str], stages: list[tuple[str, list[str]]]) -> Path:
    """Write OUT/report.html and OUT/report.md; returns the HTML path."""
    out = Path(out)
    facts = gather(out, rig, generations)
    write_text(out / "report.md", to_markdown(facts, stages, out))
    write_text(out / "report.html", to_html(facts, stages, out))
    return out / "report.html"
