"""``curate``: drive logs -> clip shards, manifest.jsonl, report.json and contact_sheet.png.

The orchestration in one place: name the logs, run the per-log stage on an executor, drop
near-duplicates across logs (deterministically, in log-name order), then write the manifest,
the report and the contact sheet atomically. Rerunning after a kill redoes only unfinished logs.
"""

from __future__ import annotations

import hashlib
import io
import shutil
import tarfile
from pathlib import Path

import numpy as np
from tqdm import tqdm

from drivewm.atomic import atomic_path, write_json
from drivewm.clips.shards import write_manifest
from drivewm.config import to_dict
from drivewm.curate import executors
from drivewm.curate.config import CurateConfig
from drivewm.curate.contact_sheet import write_contact_sheet
from drivewm.curate.dedup import near_duplicates
from drivewm.curate.stage import log_name
from drivewm.errors import DrivewmError

EXECUTORS = ("local", "ray")


def name_logs(log_paths: list[Path]) -> list[str]:
    """Unique shard names: the stem, plus a short hash of the folder where two logs share a stem."""
    stems = [log_name(p) for p in log_paths]
    return [
        s if stems.count(s) == 1 else f"{s}_{hashlib.sha1(str(Path(p).resolve().parent).encode()).hexdigest()[:6]}"
        for s, p in zip(stems, log_paths)
    ]


def curate(
    log_paths: list[Path],
    out_dir: Path,
    cfg: CurateConfig,
    executor: str = "local",
    workers: int = 1,
    ray_address: str | None = None,
    progress: bool = True,
) -> dict:
    """Curate ``log_paths`` into ``out_dir``; returns the report (also written to report.json)."""
    if executor not in EXECUTORS:
        raise DrivewmError(f"executor {executor!r}: choose one of {list(EXECUTORS)}")
    if not log_paths:
        raise DrivewmError("curate: no logs given")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    remove_leftovers(out_dir)
    jobs = [(str(p), n) for p, n in zip(log_paths, name_logs(log_paths))]
    results = _run(jobs, out_dir, cfg, executor, workers, ray_address, progress)
    rows, cross = dedup_across_logs(results, cfg.filters.dedup_cosine)
    prune_shards(out_dir, results, set(cross))
    write_manifest(out_dir, rows)
    sheet = write_contact_sheet(out_dir, rows, cfg.contact_sheet_clips)
    report = build_report(results, rows, cross, cfg, sheet)
    write_json(out_dir / "report.json", report)
    return report


def remove_leftovers(out_dir: Path) -> None:
    """Delete temporaries of a killed run (atomic_path's ``.NAME.XXXX.tmp`` folders); finished files stay."""
    for folder in (out_dir, out_dir / "logs"):
        for tmp in folder.glob(".*.tmp"):
            if tmp.is_dir():
                shutil.rmtree(tmp, ignore_errors=True)


def _run(
    jobs, out_dir: Path, cfg: CurateConfig, executor: str, workers: int, ray_address: str | None, progress: bool
) -> list[dict]:
    bar = tqdm(
        total=len(jobs),
        desc=f"curate ({executor}, {workers} worker{'s' * (workers != 1)})",
        unit="log",
        disable=not progress,
    )
    tick = lambda r: (bar.update(1), bar.set_postfix_str(f"{r['name']}: {r['status']}, {r['kept']} clips"))  # noqa: E731
    try:
        if executor == "ray":
            return executors.run_ray(jobs, str(out_dir), cfg, workers, tick, ray_address)
        return executors.run_local(jobs, str(out_dir), cfg, workers, tick)
    finally:
        bar.close()


def dedup_across_logs(results: list[dict], threshold: float) -> tuple[list[dict], dict[str, str]]:
    """Manifest rows (log-name order, then key) without clips that duplicate a clip of an earlier log.

    Returns (rows, {dropped key: key it duplicates}). Within a log the stage already de-duplicated;
    across logs the dropped clips are then removed from their shards by :func:`prune_shards`.
    """
    rows, cross, pool, pool_keys = [], {}, [], []
    for res in sorted((r for r in results if r["status"] == "ok"), key=lambda r: r["name"]):
        emb = np.asarray(res.get("embeddings", []), dtype=np.float32)
        dups = near_duplicates(emb, threshold, np.stack(pool) if pool else None) if threshold < 1 and len(emb) else []
        dup_of = {i: j for i, j, _ in dups if j < 0}
        for i, row in enumerate(res["rows"]):
            if i in dup_of:
                cross[row["key"]] = pool_keys[-1 - dup_of[i]]
                continue
            rows.append(row)
            pool.append(emb[i])
            pool_keys.append(row["key"])
    return rows, cross


def prune_shards(out_dir: Path, results: list[dict], drop: set[str]) -> None:
    """Rewrite (atomically) every shard holding a clip in ``drop`` without it; a shard left empty is
    deleted. Idempotent, so a run killed half-way converges on the rerun."""
    shards = sorted({row["shard"] for r in results if r["status"] == "ok" for row in r["rows"] if row["key"] in drop})
    for name in shards:
        path = out_dir / name
        if not path.is_file():
            continue
        with tarfile.open(path) as tar:
            members = [(m, tar.extractfile(m).read()) for m in tar if m.isfile()]
        kept = [(m, data) for m, data in members if m.name.partition(".")[0] not in drop]
        if len(kept) == len(members):
            continue
        if not kept:
            path.unlink()
            continue
        with atomic_path(path) as tmp, tarfile.open(tmp, "w") as out:
            for member, data in kept:
                out.addfile(member, io.BytesIO(data))


def build_report(
    results: list[dict], rows: list[dict], cross: dict[str, str], cfg: CurateConfig, sheet: Path | None
) -> dict:
    """report.json: totals kept/dropped by reason, and per log its status, error, warnings and sync."""
    dropped: dict[str, int] = {}
    for res in results:
        for reason, n in res.get("dropped", {}).items():
            dropped[reason] = dropped.get(reason, 0) + n
    if cross:
        dropped["near_duplicate_across_logs"] = len(cross)
    logs = {r["name"]: {k: v for k, v in r.items() if k not in ("rows", "embeddings", "name")} for r in results}
    return {
        "kept": len(rows),
        "dropped": dropped,
        "logs_ok": sum(r["status"] == "ok" for r in results),
        "logs_failed": sum(r["status"] == "failed" for r in results),
        "worst_sync_skew_ns": max((r["sync"]["worst_skew_ns"] for r in results if r["status"] == "ok"), default=0),
        "logs": logs,
        "duplicates_across_logs": cross,
        "contact_sheet": sheet.name if sheet else None,
        "config": to_dict(cfg),
    }
