"""The per-log stage: one drive log in, one shard set plus a done-marker out.

Every executor runs exactly this function per log. Its steps, in order: index the log (every
timestamp, pose and calibration, no image payloads), sync the cameras, smooth the ego poses;
then stream the images once, assembling complete ticks, and as each clip window becomes final
(valid runs cut at shot boundaries, :mod:`drivewm.curate.windows`) score and filter it,
de-duplicate within the log, blur, caption, encode and append it to the shards
``OUT/<name>-NNNNNN.tar``; last, atomically, the done-marker ``OUT/logs/<name>.json`` that lets
a rerun skip the log. Only the ticks of the window being built are held, so memory does not
grow with the log's length. A log that fails leaves no marker and no shards of its own.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import io
import json
import re
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np

from drivewm import workers
from drivewm.atomic import write_bytes, write_json
from drivewm.clips import ClipMeta, ShardWriter
from drivewm.clips.format import clip_from_arrays
from drivewm.clips.video import H264Encoder
from drivewm.config import to_dict
from drivewm.curate import dedup, filters, images, split, sync, trajectory
from drivewm.curate.captions import Captioner, ClipInfo, classify_manoeuvre, load_captioner
from drivewm.curate.config import CurateConfig
from drivewm.curate.labels import LabelFrames, labels_member
from drivewm.curate.privacy import Anonymizer
from drivewm.curate.ticks import TickAssembler, TickImages
from drivewm.curate.timing import StepClock
from drivewm.curate.windows import WindowStream
from drivewm.errors import DrivewmError
from drivewm.geometry import Rig
from drivewm.layout.build import layout_from_log, thin_road
from drivewm.layout.clip_layout import layout_to_npz
from drivewm.logs.reader import LogStream
from drivewm.logs.types import ImageFrame, LogIndex, RoadLine
from drivewm.paths import child_path, sanitize_name

MARKER_DIR = "logs"


def log_name(path: str | Path) -> str:
    """Shard/marker name of a log: its file stem made a safe name (drivewm.paths.sanitize_name)."""
    return sanitize_name(Path(path).stem, "log")


def config_fingerprint(cfg: CurateConfig) -> str:
    """Short hash of the recipe: a done-marker from another recipe does not count as done."""
    return hashlib.sha256(json.dumps(to_dict(cfg), sort_keys=True).encode()).hexdigest()[:12]


def marker_path(out_dir: Path, name: str) -> Path:
    return child_path(Path(out_dir) / MARKER_DIR, name, ext="json", what="log name")


def read_marker(out_dir: Path, name: str, cfg: CurateConfig) -> dict | None:
    """The finished result of a log from an earlier run with the same recipe, else None."""
    path = marker_path(out_dir, name)
    if not path.is_file():
        return None
    try:
        result = json.loads(path.read_text())
    except ValueError:  # a marker that is not JSON: redo the log
        return None
    if not isinstance(result, dict) or result.get("config") != config_fingerprint(cfg):
        return None
    shard = re.compile(rf"{re.escape(name)}-\d{{6}}\.tar")  # a marker only ever names this log's shards
    rows = result.get("rows")
    if not isinstance(rows, list) or not all(
        isinstance(r, dict) and shard.fullmatch(str(r.get("shard"))) for r in rows
    ):
        return None
    return result


def curate_log(log_path: str, out_dir: str, cfg: CurateConfig, name: str | None = None) -> dict:
    """Curate one log (skipping it when its done-marker exists). Never raises for bad input:
    a DrivewmError becomes ``{"status": "failed", "error": ...}``."""
    out, name = Path(out_dir), name or log_name(log_path)
    workers.reuse_freed_memory()
    done = read_marker(out, name, cfg)
    if done is not None:
        return {**done, "resumed": True}
    clock = StepClock()
    try:
        result = curate_stream(LogStream(log_path, cfg.topic_map), out, name, cfg, clock)
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


def embeddings_path(out_dir: Path, name: str) -> Path:
    """Where a log's kept-clip embeddings live (float32 (N, D), beside its done-marker)."""
    return Path(out_dir) / MARKER_DIR / f"{name}.emb.npy"


def load_embeddings(out_dir: str | Path, result: dict) -> dict:
    """``result`` with its "embeddings" file name replaced by the (N, D) float32 array, for the
    cross-log de-duplication (results and markers carry the file name: an hour of clips is
    ~20 MB of float32, not a JSON list)."""
    if result.get("status") != "ok" or not isinstance(result.get("embeddings"), str):
        return result
    return {**result, "embeddings": np.load(Path(out_dir) / result["embeddings"], allow_pickle=False)}


def curate_stream(reader: LogStream, out: Path, name: str, cfg: CurateConfig, clock: StepClock) -> dict:
    """Curate one streamed log into ``out`` (shards only; the caller writes the marker)."""
    with clock.step("index"):
        ctx = _context(reader.index(layout=True), cfg)
    for f in _stale_shards(out, name):
        f.unlink()
    kept_rows, embeddings, dropped = [], _Embeddings(), {}
    try:
        with ShardWriter(out, name, cfg.clips_per_shard) as writer:
            for start, ticks, label_maps in _stream_windows(reader, ctx, clock):
                clip, reason, emb = _make_clip(ctx, name, start, ticks, embeddings, clock, label_maps)
                if reason:
                    dropped[reason] = dropped.get(reason, 0) + 1
                    continue
                with clock.step("write"):
                    writer.write(clip)
                embeddings.add(emb)
                kept_rows.append(manifest_row(clip.meta))
    finally:
        for encoder in ctx.encoders.values():
            encoder.close()
    shard_of = dict((k, s) for s, k in writer.written)
    for row in kept_rows:
        row["shard"] = shard_of[row["key"]]
    rows = embeddings.rows()
    buf = io.BytesIO()  # rounded as the JSON lists of earlier versions were: the same dedup decisions
    np.save(buf, np.round(rows, 5) if rows is not None else np.zeros((0, 0), np.float32), allow_pickle=False)
    write_bytes(embeddings_path(out, name), buf.getvalue())
    return _result(ctx, name, kept_rows, dropped, clock)


@dataclasses.dataclass
class _LogContext:
    """What every window of one log needs."""

    log: LogIndex
    rig: Rig  # the output cameras, at the output image size
    table: sync.SyncResult
    sorted_ns: dict[str, np.ndarray]  # per camera, sorted and de-duplicated: table.frame_index points here
    smooth: trajectory.SmoothedTrajectory | None  # None: ego motion unknown
    cfg: CurateConfig
    captioner: Captioner
    anonymizer: Callable[[np.ndarray], np.ndarray] | None
    clocks: _ClockReport
    encoders: dict[str, H264Encoder] = dataclasses.field(default_factory=dict)  # h264_keep_encoder: per camera
    scene_errors: list[str] = dataclasses.field(default_factory=list)  # why clips went without a layout or labels
    road: list[RoadLine] | None = None  # the log's road lines thinned (drivewm.layout.build.thin_road), once per log


def _context(log: LogIndex, cfg: CurateConfig) -> _LogContext:
    """Sync the cameras and smooth the poses of one log, keeping what went wrong with its clocks."""
    rig = log.rig.subset(cfg.cameras) if cfg.cameras else log.rig
    if cfg.resolution:
        rig = rig.scaled(*cfg.resolution, fit="stretch")  # frames are cv2.resize-d to it (TickImages)
    empty = np.zeros(0, dtype=np.int64)
    silent = [c for c in rig.names if not len(log.image_timestamps_ns.get(c, empty))]
    if silent:
        raise DrivewmError(
            f"{log.path}: camera(s) {silent} have a calibration but no images; curate the others with cameras=[...]"
        )
    gap_ns, tol_ns = cfg.max_gap_ms * 1e6, cfg.sync_tolerance_ms * 1e6
    times, jumps, dropped = {}, {}, {}
    for c in rig.names:
        arrival = log.image_timestamps_ns.get(c, empty)
        keep, jumps[c] = sync.clock_jumps_back(arrival, gap_ns)
        times[c], dropped[c] = np.sort(arrival[keep], kind="stable"), int((~keep).sum())
    twice = [(to, high) for c in rig.names for _, high, to in jumps[c]]  # times the clock went through twice
    table = sync.synchronize(times, rig.names, cfg.period_ns, tol_ns, cfg.per_camera_offsets, gap_ns, twice)
    sorted_ns = {c: times[c][sync.dedupe_timestamps(times[c])[0]] for c in rig.names}
    smooth = trajectory.smooth_poses(log.pose_timestamps_ns, log.T_world_from_ego, cfg.trajectory)
    no_pose = np.zeros(len(table.tick_ns), dtype=bool)
    if smooth is not None:  # poses_at clamps at the ends: a tick beyond the poses has no ego motion
        no_pose = (table.tick_ns < smooth.t_ns[0] - tol_ns) | (table.tick_ns > smooth.t_ns[-1] + tol_ns)
        table.valid &= ~no_pose
    anonymizer = None
    if cfg.privacy.enabled:
        anonymizer = Anonymizer(cfg.privacy)
    clocks = _ClockReport(jumps, dropped, int(no_pose.sum()))
    return _LogContext(log, rig, table, sorted_ns, smooth, cfg, load_captioner(cfg.captioner), anonymizer, clocks)


@dataclasses.dataclass
class _ClockReport:
    """What the log's clocks did: per camera its backward jumps [(arrival index, from_ns, to_ns)]
    and the frames dropped for them; ticks outside the ego-pose span."""

    jumps_back: dict[str, list[tuple[int, int, int]]]
    dropped_frames: dict[str, int]
    ticks_without_pose: int

    def warnings(self, table: sync.SyncResult, fps: float) -> list[str]:
        """Reasons, one line each, for the clock troubles of a real rig."""
        out = []
        for cam, jumps in self.jumps_back.items():
            if jumps:
                _, high, to = jumps[0]
                out.append(
                    f"{cam}: timestamps jump back {len(jumps)} time(s) (first {(to - high) / 1e9:+.3f} s at "
                    f"{high} ns); {self.dropped_frames[cam]} frames dropped until the clock passed its earlier "
                    "maximum, ticks in the repeated time invalid"
                )
        for cam, st in table.stats.items():
            if st.get("gaps"):
                out.append(
                    f"{cam}: {st['gaps']} gap(s) longer than max_gap_ms (recorder pause or clock jump): "
                    "clips split, ticks re-anchored after each"
                )
            lo, hi = st.get("rate_p5_hz", 0.0), st.get("rate_p95_hz", 0.0)
            if lo and hi > 1.2 * lo:
                out.append(
                    f"{cam}: variable frame rate ({lo:.2f}-{hi:.2f} Hz, 5th-95th percentile; median "
                    f"{st['rate_hz']:.2f} Hz), resampled to {fps:g} fps by nearest frame"
                )
        if self.ticks_without_pose:
            out.append(f"{self.ticks_without_pose} ticks outside the ego-pose time span: invalid (no ego motion there)")
        return out


def _stream_windows(
    reader: LogStream, ctx: _LogContext, clock: StepClock
) -> Iterator[tuple[int, list[TickImages], dict[int, list[ImageFrame]]]]:
    """(first tick, [TickImages], label maps by camera index) of every final clip window, in order,
    reading the images (and label maps) once.

    Ticks are kept from the oldest one a future window may use to the newest complete one; a final
    window waits for its label maps (:class:`drivewm.curate.labels.LabelFrames`) when the log has any."""
    cfg, cam = ctx.cfg, ctx.rig.cameras[0]
    runs = [(a, b) for a, b in split.valid_runs(ctx.table.valid) if b - a >= cfg.clip_frames]
    needed = np.zeros(len(ctx.table.tick_ns), dtype=bool)
    for a, b in runs:
        needed[a:b] = True
    assembler = TickAssembler(ctx.table, ctx.sorted_ns, needed)
    labels = LabelFrames(ctx.table, ctx.log.label_timestamps_ns, needed)
    source = {c.name: (c.width, c.height) for c in ctx.log.rig.cameras}
    scales = [images.jpeg_scale(source[c.name], (c.width, c.height)) for c in ctx.rig.cameras]
    blank = _small(np.zeros((cam.height, cam.width, 3), np.uint8))
    windows = WindowStream(
        runs, cfg.clip_frames, cfg.stride_frames, cfg.fps, cfg.shot_threshold, cfg.shot_min_frames, blank
    )
    buffer: dict[int, TickImages] = {}
    pending: list[tuple[int, int, list[TickImages]]] = []  # final windows waiting for label maps
    stream = reader.stream(("image", "labels") if labels.any else ("image",))
    while True:
        with clock.step("read"):
            item = next(stream, None)
        if item is None:
            break
        if item[0] == "labels":
            labels.add(*item[1])
        for tick, frames in assembler.add(*item[1]) if item[0] == "image" else ():
            buffer[tick] = TickImages(frames, ctx.rig.cameras, clock.step, scales)
            with clock.step("shots"):
                final = windows.push(tick, functools.partial(_reference_frame, buffer[tick]))
            pending += [(start, end, [buffer[t] for t in range(start, end)]) for start, end in final]
            for t in [t for t in buffer if t < windows.oldest_needed]:
                del buffer[t]
        while pending and labels.ready(pending[0][0], pending[0][1]):
            start, end, ticks = pending.pop(0)
            yield start, ticks, labels.window(start, end)
            labels.forget_before(min([windows.oldest_needed] + [p[0] for p in pending]))
    for start, end, ticks in pending:  # the stream ended: what arrived is all there is
        yield start, ticks, labels.window(start, end)
    assembler.finish(ctx.log.path)


class _Embeddings:
    """Embeddings of the clips kept so far, as rows of one growing matrix (no re-stacking per clip)."""

    def __init__(self) -> None:
        self._rows: np.ndarray | None = None
        self.count = 0

    def add(self, emb: np.ndarray) -> None:
        if self._rows is None or self.count == len(self._rows):
            grown = np.zeros((max(16, 2 * self.count), emb.shape[0]), np.float32)
            if self._rows is not None:
                grown[: self.count] = self._rows[: self.count]
            self._rows = grown
        self._rows[self.count] = emb
        self.count += 1

    def rows(self) -> np.ndarray | None:
        """(count, D) float32, or None before the first clip."""
        return None if self._rows is None else self._rows[: self.count]


def _stale_shards(out: Path, name: str) -> list[Path]:
    """Shards of this log left by an interrupted run (rewritten from scratch, same bytes)."""
    return [p for p in out.glob(f"{name}-*.tar") if re.fullmatch(rf"{re.escape(name)}-\d{{6}}\.tar", p.name)]


def _reference_frame(tick: TickImages) -> np.ndarray | None:
    """The reference camera's frame, downscaled for shot detection; None if undecodable (the shot
    detector then sees the previous frame again; the clip is dropped later as undecodable_frame)."""
    try:
        return _small(tick.image(0))
    except DrivewmError:
        return None


def _small(img: np.ndarray, width: int = 320) -> np.ndarray:
    h = max(2, round(img.shape[0] * width / img.shape[1]))
    return cv2.resize(img, (width, h), interpolation=cv2.INTER_AREA) if img.shape[1] > width else img


def _make_clip(
    ctx: _LogContext,
    name: str,
    start: int,
    ticks: list[TickImages],
    kept: _Embeddings,
    clock: StepClock,
    label_maps: dict[int, list[ImageFrame]],
):
    """(clip or None, drop reason or None, embedding) for the ticks [start, start + len(ticks));
    ``label_maps``: camera index -> the label map (PNG) of each tick, for the cameras that have them."""
    cfg, V, T = ctx.cfg, len(ctx.rig.cameras), len(ticks)
    try:
        frames = np.stack([tick.image(v) for v in range(V) for tick in ticks])
    except DrivewmError:  # one corrupt JPEG costs its clip, not the log
        return None, "undecodable_frame", None
    frames = frames.reshape(V, T, *frames.shape[1:])  # (V, T, H, W, 3)
    t_ns = ctx.table.tick_ns[start : start + T]
    poses = ctx.smooth.poses_at(t_ns) if ctx.smooth is not None else np.tile(np.eye(4), (T, 1, 1))
    with clock.step("filters"):
        grey = np.stack([[tick.grey(v) for tick in ticks] for v in range(V)])  # (V, T, h, 160), once per frame
        scores = filters.score_grey(grey, poses[:, :3, 3] if ctx.smooth is not None else None, cfg.filters)
        reason = filters.judge(scores, cfg.filters)
        emb = dedup.grey_embedding(grey[:, dedup.key_frames(T)])
        if reason is None and cfg.filters.dedup_cosine < 1 and kept.count:
            if dedup.near_duplicates(emb[None], cfg.filters.dedup_cosine, kept.rows()):
                reason = "near_duplicate"
    if reason:
        return None, reason, emb
    if ctx.anonymizer is not None:
        with clock.step("filters"):
            frames = np.stack([[ctx.anonymizer(f) for f in cam] for cam in frames])
    meta = _meta(ctx, name, start, t_ns, poses, scores, frames)
    with clock.step("encode"):
        videos = {c.name: frames[v] for v, c in enumerate(ctx.rig.cameras)}
        h264 = (cfg.crf, cfg.h264_preset, cfg.h264_threads, cfg.h264_yuv_converter)
        clip = clip_from_arrays(meta, videos, poses, *h264, encoders=_encoders(ctx))
    with clock.step("layout"):
        clip.layout_npz = _layout(ctx, meta.key, t_ns, poses)
        clip.labels_npz = _labels(ctx, meta, label_maps)
    return clip, None, emb


def _labels(ctx: _LogContext, meta: ClipMeta, label_maps: dict[int, list[ImageFrame]]) -> dict[str, bytes]:
    """``KEY.CAMERA.labels.npz`` per camera with label maps (an undecodable one costs only its camera's
    member, kept in ``scene_errors``)."""
    out = {}
    for v, frames in label_maps.items():
        cam = ctx.rig.cameras[v]
        try:
            out[cam.name] = labels_member(
                frames, (cam.width, cam.height), meta.camera_times_ns(cam.name), f"{ctx.log.path}: {cam.name} labels"
            )
        except DrivewmError as exc:
            ctx.scene_errors.append(str(exc))
    return out


def _layout(ctx: _LogContext, key: str, t_ns: np.ndarray, poses: np.ndarray) -> bytes | None:
    """``KEY.layout.npz`` of the clip, or None: the log knows no layout, its ego motion is unknown (its
    objects cannot be put in the clip's ego frame), or the layout is bad (kept in ``scene_errors``)."""
    if ctx.smooth is None or not ctx.log.has_layout:
        return None
    try:
        if ctx.road is None:
            ctx.road = thin_road(ctx.log.road)
        return layout_to_npz(layout_from_log(ctx.log, t_ns, poses, f"{ctx.log.path}: clip {key}", road=ctx.road))
    except DrivewmError as exc:
        ctx.scene_errors.append(str(exc))
        return None


def _encoders(ctx: _LogContext) -> dict[str, H264Encoder] | None:
    """Per camera the encoder kept over the log's clips (``h264_keep_encoder``; opened with the first
    clip), or None: one encoder per clip video."""
    cfg = ctx.cfg
    if not cfg.h264_keep_encoder:
        return None
    if not ctx.encoders:
        h264 = (cfg.crf, cfg.h264_preset, cfg.h264_threads, cfg.h264_yuv_converter)
        ctx.encoders.update({c.name: H264Encoder(c.width, c.height, cfg.fps, *h264) for c in ctx.rig.cameras})
    return ctx.encoders


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


def _span_warnings(ctx: _LogContext) -> list[str]:
    """Cameras that start late or stop early by more than a clip frame: clips only cover the span where
    every camera runs, so a camera whose clock jumped (or that died) silently shortens the drive."""
    starts = {c: int(t[0]) for c, t in ctx.sorted_ns.items() if len(t)}
    ends = {c: int(t[-1]) for c, t in ctx.sorted_ns.items() if len(t)}
    out = []
    for c in starts:
        late, early = (starts[c] - min(starts.values())) * 1e-9, (max(ends.values()) - ends[c]) * 1e-9
        if max(late, early) * ctx.cfg.fps > 1:
            out.append(f"{c}: starts {late:.2f} s late and stops {early:.2f} s early; clips cover only the common span")
    return out


def _result(ctx: _LogContext, name: str, rows: list[dict], dropped: dict, clock: StepClock) -> dict:
    """The per-log result (also the done-marker's content)."""
    table, smooth = ctx.table, ctx.smooth
    warnings = list(ctx.log.warnings) + [
        f"{c}: {s['missing_ticks']} of {len(table.tick_ns)} ticks without a frame within tolerance"
        for c, s in table.stats.items()
        if s["missing_ticks"]
    ]
    warnings += [
        f"{c}: {s['duplicate_timestamps']} duplicated timestamps (kept the first)"
        for c, s in table.stats.items()
        if s.get("duplicate_timestamps")
    ]
    warnings += _span_warnings(ctx)
    warnings += ctx.clocks.warnings(table, ctx.cfg.fps)
    if ctx.scene_errors:
        warnings.append(f"{len(ctx.scene_errors)} layout(s) or label map(s) left out: {ctx.scene_errors[0]}")
    if smooth is None:
        warnings.append("no finite ego pose: ego motion unknown, motion filter skipped")
    elif smooth.missing or smooth.rejected:
        warnings.append(
            f"ego poses: {smooth.missing} NaN/missing bridged, {smooth.rejected} rejected as jitter by the Kalman gate"
        )
    if not rows:
        warnings.append("no clip kept")
    return {
        "log": str(ctx.log.path),
        "name": name,
        "status": "ok",
        "config": config_fingerprint(ctx.cfg),
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
        "camera_frames": int(sum(len(ctx.log.image_timestamps_ns.get(c, ())) for c in ctx.rig.names)),
        "cpu_s": clock.totals(),
        "embeddings": embeddings_path(Path("."), name).as_posix(),
    }
