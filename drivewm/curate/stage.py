"""The per-log stage: one drive log in, one shard set plus a done-marker out.

Every executor runs exactly this function per log. Its steps, in order: read the log, sync
the cameras, smooth the ego poses, split into clip windows (gaps, shot cuts), score and filter
each window, de-duplicate within the log, blur, caption, encode, write shards
``OUT/<name>-NNNNNN.tar``, and last, atomically, the done-marker ``OUT/logs/<name>.json`` that
lets a rerun skip the log. A log that fails leaves no marker and no shards of its own.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import re
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from drivewm.atomic import write_json
from drivewm.clips import ClipMeta, ShardWriter
from drivewm.clips.format import clip_from_arrays
from drivewm.config import to_dict
from drivewm.curate import dedup, filters, split, sync, trajectory
from drivewm.curate.captions import Captioner, ClipInfo, classify_manoeuvre, load_captioner
from drivewm.curate.config import CurateConfig
from drivewm.curate.privacy import Anonymizer
from drivewm.errors import DrivewmError
from drivewm.geometry import Rig
from drivewm.logs.reader import read_log
from drivewm.logs.types import DriveLog, ImageFrame

MARKER_DIR = "logs"


def log_name(path: str | Path) -> str:
    """Shard/marker name of a log: its file stem with anything but [A-Za-z0-9_-] replaced by '_'."""
    return re.sub(r"[^A-Za-z0-9_\-]", "_", Path(path).stem) or "log"


def config_fingerprint(cfg: CurateConfig) -> str:
    """Short hash of the recipe: a done-marker from another recipe does not count as done."""
    return hashlib.sha256(json.dumps(to_dict(cfg), sort_keys=True).encode()).hexdigest()[:12]


def marker_path(out_dir: Path, name: str) -> Path:
    return Path(out_dir) / MARKER_DIR / f"{name}.json"


def read_marker(out_dir: Path, name: str, cfg: CurateConfig) -> dict | None:
    """The finished result of a log from an earlier run with the same recipe, else None."""
    path = marker_path(out_dir, name)
    if not path.is_file():
        return None
    try:
        result = json.loads(path.read_text())
    except json.JSONDecodeError:
        return None
    return result if result.get("config") == config_fingerprint(cfg) else None


def curate_log(log_path: str, out_dir: str, cfg: CurateConfig, name: str | None = None) -> dict:
    """Curate one log (skipping it when its done-marker exists). Never raises for bad input:
    a DrivewmError becomes ``{"status": "failed", "error": ...}``."""
    out, name = Path(out_dir), name or log_name(log_path)
    done = read_marker(out, name, cfg)
    if done is not None:
        return {**done, "resumed": True}
    try:
        log = read_log(log_path, cfg.topic_map)
        result = curate_drive_log(log, out, name, cfg)
    except DrivewmError as exc:
        for shard in _stale_shards(out, name):  # shards flushed before the failure: not part of the dataset
            shard.unlink()
        return {
            "log": str(log_path),
            "name": name,
            "status": "failed",
            "error": str(exc),
            "kept": 0,
            "dropped": {},
            "rows": [],
        }
    write_json(marker_path(out, name), result)
    return result


def curate_drive_log(log: DriveLog, out: Path, name: str, cfg: CurateConfig) -> dict:
    """Curate an in-memory log into ``out`` (shards only; the caller writes the marker)."""
    log.validate()
    ctx = _context(log, cfg)
    for f in _stale_shards(out, name):
        f.unlink()
    kept_rows, embeddings, dropped = [], [], {}
    with ShardWriter(out, name, cfg.clips_per_shard) as writer:
        for start, end in _windows(ctx):
            clip, reason, emb = _make_clip(ctx, name, start, end, embeddings)
            if reason:
                dropped[reason] = dropped.get(reason, 0) + 1
                continue
            writer.write(clip)
            embeddings.append(emb)
            kept_rows.append(manifest_row(clip.meta))
    shard_of = dict((k, s) for s, k in writer.written)
    for row in kept_rows:
        row["shard"] = shard_of[row["key"]]
    return _result(log, name, cfg, ctx, kept_rows, embeddings, dropped)


@dataclasses.dataclass
class _LogContext:
    """What every window of one log needs."""

    log: DriveLog
    rig: Rig  # the output cameras, at the output image size
    table: sync.SyncResult
    frames: dict[str, list[ImageFrame]]  # per camera, de-duplicated: table.frame_index points here
    smooth: trajectory.SmoothedTrajectory | None  # None: ego motion unknown
    cfg: CurateConfig
    captioner: Captioner
    anonymizer: Callable[[np.ndarray], np.ndarray] | None

    def image(self, v: int, tick: int) -> np.ndarray:
        """Decoded uint8 RGB frame of camera ``v`` at ``tick``, at the output size."""
        cam = self.rig.cameras[v]
        img = self.frames[cam.name][self.table.frame_index[tick, v]].decode()
        if img.shape[:2] != (cam.height, cam.width):
            img = cv2.resize(img, (cam.width, cam.height), interpolation=cv2.INTER_AREA)
        return img


def _context(log: DriveLog, cfg: CurateConfig) -> _LogContext:
    """Sync the cameras and smooth the poses of one log."""
    rig = log.rig.subset(cfg.cameras) if cfg.cameras else log.rig
    if cfg.resolution:
        rig = rig.scaled(*cfg.resolution, fit="stretch")  # frames are cv2.resize-d to it (_LogContext.image)
    raw = {c: log.images.get(c, []) for c in rig.names}
    times = {c: np.array([f.timestamp_ns for f in raw[c]], dtype=np.int64) for c in rig.names}
    table = sync.synchronize(times, rig.names, cfg.period_ns, cfg.sync_tolerance_ms * 1e6, cfg.per_camera_offsets)
    frames = {c: [raw[c][i] for i in sync.dedupe_timestamps(times[c])[0]] for c in rig.names}
    smooth = trajectory.smooth_poses(log.pose_timestamps_ns, log.T_world_from_ego, cfg.trajectory)
    anonymizer = None
    if cfg.privacy.enabled:
        anonymizer = Anonymizer(cfg.privacy)
    return _LogContext(log, rig, table, frames, smooth, cfg, load_captioner(cfg.captioner), anonymizer)


def _stale_shards(out: Path, name: str) -> list[Path]:
    """Shards of this log left by an interrupted run (rewritten from scratch, same bytes)."""
    return [p for p in out.glob(f"{name}-*.tar") if re.fullmatch(rf"{re.escape(name)}-\d{{6}}\.tar", p.name)]


def _windows(ctx: _LogContext) -> list[tuple[int, int]]:
    """Clip windows (tick ranges) inside valid runs, cut at shot boundaries of the reference camera."""
    cfg, segments = ctx.cfg, []
    for a, b in split.valid_runs(ctx.table.valid):
        if b - a < cfg.clip_frames:
            continue
        cuts: list[int] = []
        if cfg.shot_threshold > 0:
            cuts = [
                a + c
                for c in split.shot_boundaries(
                    _reference_frames(ctx, a, b), cfg.fps, cfg.shot_threshold, cfg.shot_min_frames
                )
            ]
        segments += split.split_segment(a, b, cuts)
    return split.clip_windows(segments, cfg.clip_frames, cfg.stride_frames)


def _reference_frames(ctx: _LogContext, a: int, b: int):
    """Reference-camera frames of ticks [a, b) for shot detection, downscaled; an undecodable frame
    repeats the previous one (its clip is dropped later as undecodable_frame)."""
    last = None
    for t in range(a, b):
        try:
            last = _small(ctx.image(0, t))
        except DrivewmError:
            cam = ctx.rig.cameras[0]
            last = last if last is not None else _small(np.zeros((cam.height, cam.width, 3), np.uint8))
        yield last


def _small(img: np.ndarray, width: int = 320) -> np.ndarray:
    h = max(2, round(img.shape[0] * width / img.shape[1]))
    return cv2.resize(img, (width, h), interpolation=cv2.INTER_AREA) if img.shape[1] > width else img


def _make_clip(ctx: _LogContext, name: str, start: int, end: int, kept_embeddings: list[np.ndarray]):
    """(clip or None, drop reason or None, embedding) for ticks [start, end)."""
    cfg, ticks = ctx.cfg, np.arange(start, end)
    try:
        frames = np.stack(
            [np.stack([ctx.image(v, t) for t in ticks]) for v in range(len(ctx.rig.cameras))]
        )  # (V, T, H, W, 3)
    except DrivewmError:  # one corrupt JPEG costs its clip, not the log
        return None, "undecodable_frame", None
    t_ns = ctx.table.tick_ns[ticks]
    poses = ctx.smooth.poses_at(t_ns) if ctx.smooth is not None else np.tile(np.eye(4), (len(ticks), 1, 1))
    scores = filters.score_clip(frames, poses[:, :3, 3] if ctx.smooth is not None else None, cfg.filters)
    reason = filters.judge(scores, cfg.filters)
    emb = dedup.clip_embedding(frames)
    if reason is None and cfg.filters.dedup_cosine < 1 and kept_embeddings:
        if dedup.near_duplicates(emb[None], cfg.filters.dedup_cosine, np.stack(kept_embeddings)):
            reason = "near_duplicate"
    if reason:
        return None, reason, emb
    if ctx.anonymizer is not None:
        frames = np.stack([[ctx.anonymizer(f) for f in cam] for cam in frames])
    meta = _meta(ctx, name, start, t_ns, poses, scores, frames)
    clip = clip_from_arrays(meta, {c.name: frames[v] for v, c in enumerate(ctx.rig.cameras)}, poses, cfg.crf)
    return clip, None, emb


def _meta(
    ctx: _LogContext, name: str, start: int, t_ns: np.ndarray, poses: np.ndarray, scores: dict, frames: np.ndarray
) -> ClipMeta:
    cfg, known = ctx.cfg, ctx.smooth is not None
    motion = _motion(poses, t_ns) if known else {"manoeuvre": "unknown", "speed_mps": None}
    info = ClipInfo(
        dict(ctx.log.scene.tags),
        ctx.log.scene.description,
        ctx.rig.cameras,
        motion["manoeuvre"],
        motion["speed_mps"],
        frames,
    )
    caption, views = ctx.captioner.caption(info)
    waypoints, dt_s = (
        trajectory.future_waypoints(poses, t_ns, cfg.trajectory_waypoints) if known else (np.zeros((0, 3)), 0.0)
    )
    skew = int(ctx.table.skew_ns[start : start + len(t_ns)].max())
    exposures = ctx.table.frame_ns[start : start + len(t_ns)]  # (T, V) each image's own timestamp
    camera_times = (
        {}
        if (exposures == t_ns[:, None]).all()
        else {c.name: [int(t) for t in exposures[:, v]] for v, c in enumerate(ctx.rig.cameras)}
    )
    tags = {
        **{k: str(v) for k, v in ctx.log.scene.tags.items()},
        "ego_motion": "known" if known else "unknown",
        "manoeuvre": motion["manoeuvre"],
    }
    return ClipMeta(
        key=f"{name}-{start:06d}",
        source_log=str(ctx.log.path),
        start_time_ns=int(t_ns[0]),
        fps=cfg.fps,
        timestamps_ns=[int(t) for t in t_ns],
        rig=ctx.rig.to_dict(),
        caption=caption,
        view_captions=views,
        tags=tags,
        quality={k: round(float(v), 4) for k, v in scores.items()},
        sync_error_ns=skew,
        camera_timestamps_ns=camera_times,
        trajectory_ego=np.round(waypoints, 4).tolist(),
        trajectory_dt_s=dt_s,
        extra={"speed_mps": motion["speed_mps"], "description": ctx.log.scene.description},
        pair_id=pair_id(ctx.log.scene.tags, start),
    )


def pair_id(scene_tags: dict[str, str], start_tick: int) -> str:
    """``<drive_id>-t<start tick>``: the clip of the same window of the same drive in every condition
    (the scene tag ``drive_id`` of simulated logs, drivewm.sim.paired); "" when the log has none."""
    drive = scene_tags.get("drive_id", "")
    return f"{drive}-t{start_tick:06d}" if drive else ""


def _motion(poses: np.ndarray, t_ns: np.ndarray) -> dict:
    """Mean speed (m/s) and manoeuvre from per-frame poses (T, 4, 4)."""
    dt = np.diff(t_ns) * 1e-9
    speed = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1) / dt
    speed = np.concatenate([speed[:1], speed])
    yaw = np.unwrap(trajectory.rpy_of(poses)[2])
    xyz_ego0 = (poses[:, :3, 3] - poses[0, :3, 3]) @ poses[0, :3, :3]
    return {"manoeuvre": classify_manoeuvre(xyz_ego0, yaw, speed), "speed_mps": round(float(speed.mean()), 3)}


def manifest_row(meta: ClipMeta) -> dict:
    """One manifest.jsonl row: enough to filter and balance without opening shards."""
    return {
        "key": meta.key,
        "shard": "",
        "source_log": meta.source_log,
        "start_time_ns": meta.start_time_ns,
        "num_frames": meta.num_frames,
        "fps": meta.fps,
        "duration_s": round(meta.num_frames / meta.fps, 4),
        "cameras": meta.cameras,
        "tags": meta.tags,
        "quality": meta.quality,
        "caption": meta.caption,
        "sync_error_ns": meta.sync_error_ns,
        "pair_id": meta.pair_id,
    }


def _result(
    log: DriveLog, name: str, cfg: CurateConfig, ctx: _LogContext, rows: list[dict], embeddings: list, dropped: dict
) -> dict:
    """The per-log result (also the done-marker's content)."""
    table, smooth = ctx.table, ctx.smooth
    warnings = [
        f"{c}: {s['missing_ticks']} of {len(table.tick_ns)} ticks without a frame within tolerance"
        for c, s in table.stats.items()
        if s["missing_ticks"]
    ]
    warnings += [
        f"{c}: {s['duplicate_timestamps']} duplicated timestamps (kept the first)"
        for c, s in table.stats.items()
        if s.get("duplicate_timestamps")
    ]
    if smooth is None:
        warnings.append("no finite ego pose: ego motion unknown, motion filter skipped")
    elif smooth.missing or smooth.rejected:
        warnings.append(
            f"ego poses: {smooth.missing} NaN/missing bridged, {smooth.rejected} rejected as jitter by the Kalman gate"
        )
    if not rows:
        warnings.append("no clip kept")
    return {
        "log": str(log.path),
        "name": name,
        "status": "ok",
        "config": config_fingerprint(cfg),
        "kept": len(rows),
        "dropped": dropped,
        "warnings": warnings,
        "rows": rows,
        "sync": {
            "ticks": int(len(table.tick_ns)),
            "valid_ticks": int(table.valid.sum()),
            "worst_skew_ns": table.worst_skew_ns,
            "cameras": table.stats,
        },
        "embeddings": [np.round(e, 5).tolist() for e in embeddings],
    }
