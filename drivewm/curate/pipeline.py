"""``curate``: drive logs -> clip shards, manifest.jsonl, report.json and contact_sheet.png.

The orchestration in one place: lock the output folder (drivewm.lock: a second run on the same
``--out`` is refused), give every distinct log a distinct name (a log given twice is curated once),
run the per-log stage on an executor, drop near-duplicates across logs (deterministically, in
log-name order), then write the manifest (checked against the shards), the report and the contact
sheet atomically. Rerunning after a kill redoes only unfinished logs.
"""

from __future__ import annotations

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
from drivewm.errors import DrivewmError
from drivewm.lock import folder_lock
from drivewm.paths import child_path, distinct_paths, unique_names

EXECUTORS = ("local", "ray")


def name_logs(log_paths: list[Path]) -> list[str]:
    """Distinct shard names for distinct logs: the file stem made safe, plus a short hash of the resolved
    path where two logs would share a name (``drive a.mcap`` and ``drive_a.mcap``, ``x/a.mcap`` and ``y/a.mcap``)."""
    return unique_names([Path(p).stem for p in log_paths], [str(Path(p).resolve()) for p in log_paths], "log")


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
    logs, warnings = distinct_paths(log_paths)
    with folder_lock(out_dir, "curate"):
        remove_leftovers(out_dir)
        jobs = [(str(p), n) for p, n in zip(logs, name_logs(logs))]
        results = _run(jobs, out_dir, cfg, executor, workers, ray_address, progress)
        remove_leftovers(out_dir)  # a worker killed mid-log (then retried) left its temporary shard
        rows, cross = dedup_across_logs(results, cfg.filters.dedup_cosine)
        prune_shards(out_dir, results, set(cross))
        check_manifest(out_dir, rows)
        write_manifest(out_dir, rows)
        sheet = write_contact_sheet(out_dir, rows, cfg.contact_sheet_clips)
        report = build_report(results, rows, cross, cfg, sheet)
        report["warnings"] = warnings
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
    ok = sorted((r for r in results if r["status"] == "ok"), key=lambda r: r["name"])
    names = [r["name"] for r in ok]
    if len(set(names)) != len(names):  # one log twice would drop every clip as a duplicate of itself
        raise DrivewmError(f"curate: two logs share a name in {names}")
    for res in ok:
        emb = np.asarray(res.get("embeddings", []), dtype=np.float32)
        dups = near_duplicates(emb, threshold, np.stack(pool) if pool else None) if threshold < 1 and len(emb) else []
        dup_of = {i: j for i, j, _ in dups if j < 0}
        for i, row in enumerate(res["rows"]):
            if i in dup_of and pool_keys[-1 - dup_of[i]] != row["key"]:
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
        path = child_path(out_dir, name.removesuffix(".tar"), ext="tar")
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


def check_manifest(out_dir: Path, rows: list[dict]) -> None:
    """Every manifest row must name a shard that exists and holds its clip: a manifest listing a
    deleted shard (or a clip pruned from one) would break every reader of the dataset."""
    members: dict[str, set[str]] = {}
    for shard in sorted({r["shard"] for r in rows}):
        try:
            with tarfile.open(child_path(out_dir, shard.removesuffix(".tar"), ext="tar")) as tar:
                members[shard] = {m.name.partition(".")[0] for m in tar}
        except (tarfile.TarError, OSError):
            members[shard] = set()
    lost = [f"{r['key']} ({r['shard']})" for r in rows if r["key"] not in members[r["shard"]]]
    if lost:
        raise DrivewmError(f"{out_dir}: manifest rows without their clip in a shard: {lost[:5]}")


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
