"""The quickstart report: one HTML page and its Markdown twin over a pipeline output folder.

It reads only the files the stages wrote (curation report.json, tokenizer metrics.json, training
metrics.jsonl, eval metrics.json, contact sheets), so it can be rebuilt at any time. Real clips, the
shipped model's and the fine-tuned model's samples stand side by side: one metrics column each (a
metric eval could not compute is a dash with a footnote saying why) and their contact sheets in
one row per prompt. A generated set's column names the post-steps its clips went through (their
metadata's ``post_processing``): "network's own frames" when none did, so post-processed samples never
pass for the network's. The first curated clip transferred to snow (``drivewm transfer``) is a figure,
and the transfer model's training curve sits beside the fine-tuning one. "Commands run" is a block
a user pastes into a shell in the output folder: shlex-quoted, paths relative to that folder,
shipped models spelled ``shipped:KIND``. Figures are linked relatively; the page counts its own
loaded figures on ``load`` (``data-figures-loaded``), which the browser test reads.
"""

from __future__ import annotations

import html
import json
import math
import os
import shlex
from collections import Counter
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from drivewm.atomic import atomic_path, read_jsonl, write_text  # noqa: E402

#: Eval metrics shown in the real-vs-generated table, with their meaning and unit.
EVAL_ROWS = {
    "tse": "temporal Sampson error (px, lower is better)",
    "tse_calibrated": "TSE under the conditioned trajectory (px, lower is better)",
    "cse": "cross-view Sampson error (px, lower is better)",
    "cse_calibrated": "CSE under the rig's calibration (px, lower is better)",
    "pose_success": "pose-estimation success (fraction of clips)",
    "ate": "absolute trajectory error (m)",
    "rpe_trans": "relative pose error, translation (m)",
    "rpe_rot": "relative pose error, rotation (deg)",
    "tfe": "trajectory-following error (m)",
    "turn_sign": "turning clips whose yaw, read from the frames, has the asked (or logged) sign (fraction)",
    "adherence_weather": "weather asked for, recognised (fraction)",
    "adherence_time_of_day": "time of day asked for, recognised (fraction)",
}
#: Column titles of the evaluated sets (OUT/eval/NAME).
SET_TITLES = {"real": "real clips", "shipped": "shipped model", "finetuned": "fine-tuned model"}


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


def pooled_metrics(paths: list[Path]) -> dict:
    """One metrics dict over the clips of several eval outputs (keys ``FOLDER/CLIP``), aggregated
    by eval's own rule (drivewm.eval.suite.aggregate); {} when none of them exists."""
    from drivewm.eval.suite import ClipResult, aggregate  # the eval stack, only when a report is written

    clips = {f"{p.parent.name}/{k}": c for p in paths for k, c in _read_json(p).get("clips", {}).items()}
    return {**aggregate([ClipResult(k, c, {}) for k, c in clips.items()]), "clips": clips} if clips else {}


def post_processing(manifests: list[Path]) -> list[str]:
    """Every post-step named in the ``post_processing`` of the clips in ``manifests`` (generate's
    manifest.jsonl files), in first-seen order; [] when none was applied."""
    steps: list[str] = []
    for path in (m for m in manifests if m.is_file()):
        for row in read_jsonl(path):
            steps += [s for s in row.get("post_processing") or [] if s not in steps]
    return steps


def set_title(name: str, facts: dict) -> str:
    """Column title of an evaluated set: a generated set's says whether it is the network's own frames."""
    title = SET_TITLES.get(name, name)
    if name not in facts.get("post_processing", {}):
        return title
    steps = facts["post_processing"][name]
    return f"{title}, post-processed: {', '.join(steps)}" if steps else f"{title}, network's own frames"


def gather(out: Path, rig: str, generations: list[str], models: list[str]) -> dict:
    """Every number and figure the report shows, from the stage outputs in ``out``; ``models`` are
    the generating models (folders under OUT/generated/ and OUT/eval/)."""
    figures = {}
    for first in sorted((out / "tokenizer_eval").glob("*.png"))[:1]:
        figures["Shipped tokenizer on the simulated clips (input | output)"] = first
    curves = training_curves(out, out / "training_curves.png")
    if curves:
        figures["Training curves"] = curves
    sheets = {
        name: {"real": out / "clips" / "contact_sheet.png"}
        | {m: out / "generated" / m / name / "contact_sheet.png" for m in models}
        for name in generations
    }
    transferred = _read_json(out / "transfer" / "report.json")
    if transferred.get("written"):
        what = f"Transferred: {transferred['written'][0]} (source above, transferred below, all views)"
        figures[what] = out / "transfer" / "contact_sheet.png"
    sets = {
        "real": _read_json(out / "eval" / "real" / "metrics.json"),
        **{m: pooled_metrics([out / "eval" / m / g / "metrics.json" for g in generations]) for m in models},
    }
    return {
        "rig": rig,
        "curate": _read_json(out / "clips" / "report.json"),
        "tokenizer": _read_json(out / "tokenizer_eval" / "metrics.json"),
        "eval": {name: with_turn_sign(metrics) for name, metrics in sets.items()},
        "post_processing": {
            m: post_processing([out / "generated" / m / g / "manifest.jsonl" for g in generations]) for m in models
        },
        "figures": {k: v for k, v in figures.items() if v.is_file()},
        "sheets": {g: {m: p for m, p in row.items() if p.is_file()} for g, row in sheets.items()},
        "recording": out / "drive.rrd",
    }


def with_turn_sign(metrics: dict) -> dict:
    """``metrics`` with ``turn_sign``: the world-model benchmark's turn-sign figure
    (drivewm.product.figures.trajectory_figures) over its clips, None where none turns."""
    from drivewm.product.figures import trajectory_figures

    if not metrics:
        return metrics
    figure = trajectory_figures(list((metrics.get("clips") or {}).values()), {})["turn_sign_rate"]
    return {**metrics, "turn_sign": figure["value"]}


#: The per-clip status entry that says why a metric has no value (eval's metrics.json); other keys
#: use their own entry, else their base metric's (``cse_calibrated`` -> ``cse``).
STATUS_OF = {"ate": "traj", "rpe_trans": "traj", "rpe_rot": "traj", "tfe": "traj"}


def _missing_reason(metrics: dict, key: str) -> str:
    """Why ``key`` has no aggregate: the most common per-clip status and in how many clips it was
    given, e.g. 'too_few_matches (2 of 2 clips)'."""
    reasons: Counter = Counter()
    clips = (metrics.get("clips") or {}).values()
    field = key.removeprefix("adherence_")
    if field != key and not any(f"{field}_match" in (c.get("adherence") or {}) for c in clips):
        return f"no prompt or clip tag names a {field.replace('_', ' ')}"
    if key == "turn_sign":
        from drivewm.product.figures import TURN_DEG

        return f"no clip's trajectory turns by more than the benchmark's {TURN_DEG:g} degrees"
    for clip in clips:
        statuses = clip.get("status") or {}
        status = statuses.get(STATUS_OF.get(key, key)) or statuses.get(key.split("_")[0])
        if isinstance(status, dict):
            reasons.update({r: 1 for r, n in status.items() if r != "ok" and n})
        elif status and status != "ok":
            reasons[status] += 1
    if not reasons:
        return "eval gave no value for any clip (no per-clip status says why)"
    reason, n = reasons.most_common(1)[0]
    return f"{reason} ({n} of {len(clips)} clips)"


def _eval_table(facts: dict) -> tuple[list[str], list[list[str]], list[str]]:
    """Header (metric, meaning, one column per evaluated set), rows for the metrics present, and
    footnotes: a metric eval could not compute is a dash with a footnote naming the reason."""
    sets = facts["eval"]
    header = [
        "metric",
        "meaning",
        *[f"{set_title(n, facts)} ({m.get('num_clips', 0)} clips)" for n, m in sets.items()],
    ]
    notes: list[str] = []
    rows = []
    for key in (k for k in EVAL_ROWS if any(k in m for m in sets.values())):
        cells = []
        for name, metrics in sets.items():
            value = metrics.get(key)
            if value is not None and math.isfinite(value):  # NaN: eval's pooled mean over no finite clip value
                cells.append(_fmt(value))
                continue
            why = _missing_reason(metrics, key) if metrics else "no metrics.json (its eval stage did not run)"
            note = f"{SET_TITLES.get(name, name)}, `{key}`: {why}"
            notes += [] if note in notes else [note]
            cells.append(f"— [{notes.index(note) + 1}]")
        rows.append([key, EVAL_ROWS[key], *cells])
    return header, rows, notes


def relative_argv(argv: list[str], out: Path) -> list[str]:
    """``argv`` with every path inside ``out`` made relative to it (``out`` itself is ``.``)."""
    root = str(out)
    return ["." if a == root else a[len(root) + 1 :] if a.startswith(root + os.sep) else a for a in argv]


def command_lines(stages: list[tuple[str, list[str]]], out: Path) -> list[str]:
    """The stages as lines to paste into a shell in ``out``: a comment saying so, then one
    shlex-quoted ``drivewm ...`` line per stage."""
    lines = ["# run in the quickstart's output folder (the folder of this report)"]
    return lines + [shlex.join(["drivewm", *relative_argv(argv, out)]) for _, argv in stages]


def _curate_line(curate: dict) -> str:
    kept = curate.get("kept", curate.get("clips_kept", "n/a"))
    dropped = curate.get("dropped", {})
    if isinstance(dropped, dict):
        dropped = ", ".join(f"{r}: {n}" for r, n in sorted(dropped.items())) or "none"
    return f"clips kept: {kept}; dropped by reason: {dropped}"


def _sheet_rows(facts: dict) -> tuple[list[str], list[tuple[str, list[Path | None]]]]:
    """Header (prompt, then real / shipped / fine-tuned) and one row of contact sheets per prompt."""
    sets = list(facts["eval"])
    rows = [(name, [sheets.get(s) for s in sets]) for name, sheets in facts["sheets"].items()]
    return ["prompt", *[set_title(s, facts) for s in sets]], rows


def to_markdown(facts: dict, stages: list[tuple[str, list[str]]], out: Path) -> str:
    tok = facts["tokenizer"]
    lines = [
        "# drivewm quickstart report",
        "",
        f"Rig: `{facts['rig']}`. The shipped multi-view model, fine-tuned on the simulated clips, next to",
        "the shipped model itself and the real (simulated) clips.",
        "",
        "## Curation",
        "",
        _curate_line(facts["curate"]),
        "",
        "## Shipped tokenizer",
        "",
        f"PSNR {_fmt(tok.get('psnr'))} dB, SSIM {_fmt(tok.get('ssim'))} on the simulated held-out clips",
        "",
        "## Consistency benchmark: real, shipped, fine-tuned",
        "",
    ]
    header, rows, notes = _eval_table(facts)
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join([f"`{r[0]}`", *r[1:]]) + " |" for r in rows]
    lines += ["", *[f"[{i}] {n}  " for i, n in enumerate(notes, 1)], ""]
    sheet_header, sheet_rows = _sheet_rows(facts)
    lines += ["## Contact sheets: real, shipped, fine-tuned", "", "| " + " | ".join(sheet_header) + " |"]
    lines += ["|" + "---|" * len(sheet_header)]
    for name, paths in sheet_rows:
        cells = [f"![{name}]({p.relative_to(out)})" if p else "(missing)" for p in paths]
        lines.append("| " + " | ".join([f"`{name}`", *cells]) + " |")
    lines += ["", "## Figures", ""]
    lines += [f"### {title}\n\n![{title}]({path.relative_to(out)})\n" for title, path in facts["figures"].items()]
    lines += ["## Rerun recording", "", f"`{facts['recording'].name}` (open with `rerun {facts['recording'].name}`)"]
    lines += ["", "## Commands run", "", "```sh", *command_lines(stages, out), "```", ""]
    return "\n".join(lines)


def _html_sheets(facts: dict, out: Path) -> str:
    """The contact sheets as a table: a row per prompt, a column per evaluated set."""
    e = html.escape
    header, rows = _sheet_rows(facts)
    body = "".join(
        f"<tr><td><code>{e(name)}</code></td>"
        + "".join(
            f"<td><img src='{e(str(p.relative_to(out)))}' alt='{e(name)}: {e(h)}'></td>" if p else "<td>missing</td>"
            for h, p in zip(header[1:], paths)
        )
        + "</tr>"
        for name, paths in rows
    )
    return "<table id='sheets'><tr>" + "".join(f"<th>{e(h)}</th>" for h in header) + f"</tr>{body}</table>"


def to_html(facts: dict, stages: list[tuple[str, list[str]]], out: Path) -> str:
    e = html.escape
    tok = facts["tokenizer"]
    header, table, notes = _eval_table(facts)
    head = "".join(f"<th>{e(h)}</th>" for h in header)
    rows = "".join(
        "<tr><td><code>" + e(r[0]) + "</code></td>" + "".join(f"<td>{e(c)}</td>" for c in r[1:]) + "</tr>"
        for r in table
    )
    footnotes = "".join(f"<li>{e(n)}</li>" for n in notes)
    figs = "".join(
        f"<figure><img src='{e(str(p.relative_to(out)))}' alt='{e(t)}'><figcaption>{e(t)}</figcaption></figure>"
        for t, p in facts["figures"].items()
    )
    n_figures = len(facts["figures"]) + sum(len(row) for row in facts["sheets"].values())
    cmds = e("\n".join(command_lines(stages, out)))
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>drivewm quickstart report</title>
<style>body{{font-family:system-ui,sans-serif;max-width:1800px;margin:2em auto;padding:0 1em;color:#222}}
table{{border-collapse:collapse}}td,th{{border:1px solid #ccc;padding:4px 10px;text-align:left;vertical-align:top}}
figure{{margin:1.5em 0}}img{{max-width:100%;border:1px solid #ddd}}
pre{{background:#f6f6f6;padding:1em;overflow:auto}}</style></head>
<body data-figures="{n_figures}">
<h1>drivewm quickstart report</h1>
<p>Rig <code>{e(facts["rig"])}</code>: the shipped multi-view model, fine-tuned on the simulated clips, next to the
shipped model itself and the real (simulated) clips. <span id="figure-status">loading figures...</span></p>
<h2>Curation</h2><p>{e(_curate_line(facts["curate"]))}</p>
<h2>Shipped tokenizer</h2><p>PSNR {e(_fmt(tok.get("psnr")))} dB, SSIM {e(_fmt(tok.get("ssim")))} on the simulated
held-out clips.</p>
<h2>Consistency benchmark: real, shipped, fine-tuned</h2>
<table id="eval-table"><tr>{head}</tr>{rows}</table><ol id="eval-notes">{footnotes}</ol>
<h2>Contact sheets: real, shipped, fine-tuned</h2>{_html_sheets(facts, out)}
<h2>Figures</h2>{figs}
<h2>Rerun recording</h2><p><code>{e(facts["recording"].name)}</code> (open with <code>rerun</code>)</p>
<h2>Commands run</h2><pre id="commands">{cmds}</pre>
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


def write_report(
    out: Path, rig: str, generations: list[str], models: list[str], stages: list[tuple[str, list[str]]]
) -> Path:
    """Write OUT/report.html and OUT/report.md; returns the HTML path. ``models`` name the generating
    models (OUT/generated/MODEL/GENERATION, OUT/eval/MODEL); ``stages`` are the commands that ran."""
    out = Path(out)
    facts = gather(out, rig, generations, models)
    write_text(out / "report.md", to_markdown(facts, stages, out))
    write_text(out / "report.html", to_html(facts, stages, out))
    return out / "report.html"
