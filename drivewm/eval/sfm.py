"""Structure from motion on a clip with pycolmap (COLMAP 4): the engine behind pose success and trajectories.

The rig's intrinsics and extrinsics are known, so registration only has to find the ego motion:
every camera keeps its calibration fixed (a COLMAP camera model that carries its distortion:
PINHOLE, OPENCV or FULL_OPENCV), and a COLMAP rig config (``apply_rig_config``: each camera's
``cam_from_rig`` from the extrinsics, held fixed in bundle adjustment) ties the views of one
timestamp into one frame. Features come from the benchmark's own matcher (``features='shared'``, the
protocol): the SIFT keypoints and matches that TSE and CSE already computed
(drivewm.eval.matching.FrameMatcher caches both), geometrically verified by the same robust F fit
(``verify='drivewm'``), are written into the COLMAP database, so COLMAP neither extracts nor
matches: pairs are each camera's frame t with t + each of ``temporal_gaps``, the overlapping camera
pairs at each t and, for the metric scale, across one frame (``cross_gaps``). ``features='colmap'``
(2.2x the pose CPU; what a learned matcher, which has no per-image keypoints,
needs) writes PNGs and runs COLMAP's SIFT extraction and sequential matching,
rig images expanded.

COLMAP puts pixel centres at half-integers (the top-left pixel's centre is (0.5, 0.5)); drivewm at
integers (OpenCV), so principal points and keypoints get +0.5 on the way in.
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
from threadpoolctl import threadpool_limits

from drivewm.errors import DrivewmError
from drivewm.eval.config import EpipolarConfig, PoseConfig
from drivewm.geometry import Camera, Rig, invert_T, make_T

#: COLMAP models by the number of OpenCV distortion coefficients (k1, k2, p1, p2[, k3, k4, k5, k6]).
COLMAP_MODELS = {4: "OPENCV", 8: "FULL_OPENCV"}


@dataclasses.dataclass
class SfmResult:
    """Reconstruction of one clip: ``T_world_from_cam`` per camera (T, 4, 4) in the SfM's own world
    frame and scale (NaN where a frame did not register), ``registered`` per camera (T,) bool, and
    wall ``seconds`` of its two stages: ``database`` (features, matches and their verification into
    COLMAP's database; with shared features, the part TSE and CSE did not already compute) and
    ``mapping`` (COLMAP's incremental mapper)."""

    T_world_from_cam: dict[str, np.ndarray]
    registered: dict[str, np.ndarray]
    seconds: dict[str, float] = dataclasses.field(default_factory=dict)

    @property
    def registered_fraction(self) -> float:
        return float(np.mean(np.concatenate(list(self.registered.values()))))

    @property
    def all_registered(self) -> bool:
        return all(bool(r.all()) for r in self.registered.values())


def colmap_camera(camera: Camera):
    """A fixed-calibration pycolmap.Camera: PINHOLE without distortion, OPENCV for (k1, k2, p1, p2),
    FULL_OPENCV for up to 8 coefficients (k3 and beyond); principal point shifted by +0.5 px."""
    import pycolmap

    fx, fy, cx, cy = camera.K[0, 0], camera.K[1, 1], camera.K[0, 2] + 0.5, camera.K[1, 2] + 0.5
    dist = np.asarray(camera.distortion, dtype=np.float64).reshape(-1)
    if not np.any(dist):
        model, params = "PINHOLE", [fx, fy, cx, cy]
    elif len(dist) in (4, 5, 8):
        n = 4 if len(dist) == 4 else 8
        model, params = COLMAP_MODELS[n], [fx, fy, cx, cy, *np.pad(dist, (0, n - len(dist)))]
    else:
        raise DrivewmError(
            f"camera {camera.name}: {len(dist)} distortion coefficients; structure from motion takes OpenCV's "
            "4, 5 or 8 (k1, k2, p1, p2[, k3[, k4, k5, k6]])"
        )
    return pycolmap.Camera(model=model, width=camera.width, height=camera.height, params=params)


def run_sfm(
    videos: dict[str, np.ndarray],
    rig: Rig,
    cfg: PoseConfig,
    rig_aware: bool = True,
    matcher=None,
    epi_cfg: EpipolarConfig | None = None,
    pairs: list[tuple[str, str]] | None = None,
    database_ready: Callable[[], None] | None = None,
) -> SfmResult:
    """Reconstruct the clip. ``videos``: uint8 RGB (T, H, W, 3) per camera of ``rig`` (rig order).
    ``matcher``: the FrameMatcher whose features to share (a new SIFT one if None); ``pairs``: the
    overlapping camera pairs (drivewm.eval.consistency.overlapping_pairs if None);
    ``database_ready``: called once the database is written (or failed), before the one-thread mapping."""
    import pycolmap

    from drivewm.eval.matching import FrameMatcher

    pycolmap.set_random_seed(cfg.seed)
    pycolmap.logging.minloglevel = max(pycolmap.logging.minloglevel, 2)  # COLMAP's INFO lines drown the progress bar
    matcher = matcher or FrameMatcher(_default_match_cfg())
    shared = cfg.features == "shared" and matcher.shares_features
    t0 = time.perf_counter()
    with threadpool_limits(limits=1), tempfile.TemporaryDirectory(prefix="drivewm-sfm-") as tmp:
        tmp = Path(tmp)
        images, db_path = tmp / "images", tmp / "database.db"
        images.mkdir()
        try:
            _write_database(pycolmap, db_path, images, videos, rig, cfg, rig_aware, matcher, epi_cfg, pairs, shared)
        finally:
            if database_ready is not None:
                database_ready()
        t1 = time.perf_counter()
        models = _map(pycolmap, db_path, images, tmp / "sparse", cfg)
        t2 = time.perf_counter()
    num_frames = len(next(iter(videos.values())))
    result = _poses_from_models(models, rig, num_frames)
    result.seconds = {"database": t1 - t0, "mapping": t2 - t1}
    return result


def _write_database(pycolmap, db_path, images, videos, rig, cfg, rig_aware, matcher, epi_cfg, pairs, shared) -> None:
    """The COLMAP database the mapper reads: shared features and verified matches, or COLMAP's own."""
    if shared:
        names = _write_shared(pycolmap, db_path, videos, rig, cfg, matcher, epi_cfg or EpipolarConfig(), pairs)
    else:
        _write_frames(videos, images)
        for cam in rig.cameras:
            _extract(pycolmap, db_path, images, cam, len(videos[cam.name]), cfg)
    if rig_aware and len(rig.cameras) > 1:
        _apply_rig(pycolmap, db_path, rig)
    if not shared:
        _match(pycolmap, db_path, cfg, rig_aware)
    elif cfg.verify == "colmap":
        _verify(pycolmap, db_path, names, cfg)


def _default_match_cfg():
    from drivewm.eval.config import MatchConfig

    return MatchConfig()


def sfm_image_pairs(rig: Rig, num_frames: int, cfg: PoseConfig, pairs: list[tuple[str, str]]) -> list[tuple]:
    """((camera, t), (camera, u)) pairs to match: each camera's frame t with t + gap
    (``temporal_gaps``), and each overlapping camera pair at t with itself at t and, both ways, at
    t + gap (``cross_gaps``). Cross-camera tracks are what fix the metric scale: with cameras that
    share no points, a rig moving straight ahead has no observable scale (and no steady one)."""
    T = num_frames
    out = [((c, t), (c, t + g)) for c in rig.names for g in cfg.temporal_gaps for t in range(T - g)]
    out += [((a, t), (b, t)) for a, b in pairs for t in range(T)]
    for g in cfg.cross_gaps:
        out += [(x, y) for a, b in pairs for t in range(T - g) for x, y in (((a, t), (b, t + g)), ((b, t), (a, t + g)))]
    return out


def _write_shared(pycolmap, db_path: Path, videos, rig: Rig, cfg: PoseConfig, matcher, epi_cfg, pairs) -> list[str]:
    """Cameras, images, the matcher's keypoints and matches (F-verified for verify='drivewm') into a
    new COLMAP database; returns the image-name pairs written ("CAM/TTTT.png CAM/TTTT.png")."""
    from drivewm.eval.consistency import native_px_per_canonical_px, overlapping_pairs
    from drivewm.eval.epipolar import canonical_K, frame_pair_fit, rectify_matches
    from drivewm.eval.matching import Matches

    num_frames = len(next(iter(videos.values())))
    pairs = overlapping_pairs(rig, _consistency_cfg()) if pairs is None else pairs
    K_c = canonical_K(epi_cfg)

    def verified_pair(pair: tuple) -> np.ndarray:
        """Keypoint index pairs (N, 2) of a's and b's shared features, the drivewm-verified ones."""
        a, b = pair
        idx = matcher.match_indices(a, videos[a[0]][a[1]], b, videos[b[0]][b[1]])
        if cfg.verify == "drivewm":
            fa, fb = matcher.features(a, None), matcher.features(b, None)
            m = rectify_matches(Matches(fa.uv[idx[:, 0]], fb.uv[idx[:, 1]]), rig.camera(a[0]), rig.camera(b[0]), K_c)
            scale = 0.5 * sum(native_px_per_canonical_px(rig.camera(c), K_c) for c in (a[0], b[0]))
            _, keep = frame_pair_fit(matcher, a, b, m, epi_cfg, scale)
            idx = idx[keep]
        return idx

    matcher.prefetch(videos)
    db = pycolmap.Database.open(db_path)
    try:
        ids = {}
        for cam in rig.cameras:
            camera_id = db.write_camera(colmap_camera(cam))
            for t in range(num_frames):
                image_id = db.write_image(pycolmap.Image(name=f"{cam.name}/{t:04d}.png", camera_id=camera_id))
                ids[(cam.name, t)] = image_id
                uv = matcher.features((cam.name, t), videos[cam.name][t]).uv
                db.write_keypoints(image_id, (uv + 0.5).astype(np.float32))
        image_pairs = sfm_image_pairs(rig, num_frames, cfg, pairs)
        names = []
        for (a, b), idx in zip(image_pairs, matcher.map(verified_pair, image_pairs)):
            if len(idx) < cfg.min_pair_inliers:
                continue
            db.write_matches(ids[a], ids[b], idx.astype(np.uint32))
            if cfg.verify == "drivewm":
                geometry = pycolmap.TwoViewGeometry()
                geometry.config = pycolmap.TwoViewGeometryConfiguration.UNCALIBRATED
                geometry.inlier_matches = idx.astype(np.uint32)
                db.write_two_view_geometry(ids[a], ids[b], geometry)
            names.append(f"{a[0]}/{a[1]:04d}.png {b[0]}/{b[1]:04d}.png")
    finally:
        db.close()
    return names


def _verify(pycolmap, db_path: Path, names: list[str], cfg: PoseConfig) -> None:
    """COLMAP's geometric verification of the written matches (after the rig config, so it knows the cameras)."""
    pairs_path = db_path.parent / "pairs.txt"
    pairs_path.write_text("\n".join(names) + "\n")
    options = pycolmap.TwoViewGeometryOptions()
    options.ransac.random_seed = cfg.seed
    options.ransac.num_threads = 1
    options.ransac.max_num_trials = cfg.verify_max_trials
    pycolmap.verify_matches(db_path, pairs_path, options)


def _consistency_cfg():
    from drivewm.eval.config import ConsistencyConfig

    return ConsistencyConfig()


def _write_frames(videos: dict[str, np.ndarray], images: Path) -> None:
    for cam, frames in videos.items():
        (images / cam).mkdir(parents=True, exist_ok=True)
        for t, frame in enumerate(frames):
            cv2.imwrite(str(images / cam / f"{t:04d}.png"), cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))


def _extract(pycolmap, db_path: Path, images: Path, cam: Camera, num_frames: int, cfg: PoseConfig) -> None:
    colmap_cam = colmap_camera(cam)
    params = ",".join(repr(float(p)) for p in colmap_cam.params)
    reader = pycolmap.ImageReaderOptions(camera_model=colmap_cam.model.name, camera_params=params)
    extraction = pycolmap.FeatureExtractionOptions(num_threads=1)
    extraction.sift.max_num_features = cfg.max_features
    names = [f"{cam.name}/{t:04d}.png" for t in range(num_frames)]
    pycolmap.extract_features(
        db_path,
        images,
        image_names=names,
        camera_mode=pycolmap.CameraMode.SINGLE,
        reader_options=reader,
        extraction_options=extraction,
        device=pycolmap.Device.cpu,
    )


def _apply_rig(pycolmap, db_path: Path, rig: Rig) -> None:
    """One COLMAP rig: the first camera is the reference sensor; cam_from_rig = T_cam_from_ref."""
    ref = rig.cameras[0]
    cams = []
    for i, cam in enumerate(rig.cameras):
        rc = pycolmap.RigConfigCamera(ref_sensor=(i == 0), image_prefix=f"{cam.name}/")
        if i:
            T = invert_T(cam.T_ego_from_cam) @ ref.T_ego_from_cam
            rc.cam_from_rig = pycolmap.Rigid3d(pycolmap.Rotation3d(T[:3, :3]), T[:3, 3])
        cams.append(rc)
    db = pycolmap.Database.open(db_path)
    try:
        pycolmap.apply_rig_config([pycolmap.RigConfig(cameras=cams)], db)
    finally:
        db.close()


def _match(pycolmap, db_path: Path, cfg: PoseConfig, rig_aware: bool) -> None:
    matching = pycolmap.FeatureMatchingOptions(num_threads=1)
    pairing = pycolmap.SequentialPairingOptions(overlap=cfg.sequential_overlap, quadratic_overlap=False)
    pairing.expand_rig_images = rig_aware
    pycolmap.match_sequential(db_path, matching_options=matching, pairing_options=pairing, device=pycolmap.Device.cpu)


def _map(pycolmap, db_path: Path, images: Path, out: Path, cfg: PoseConfig) -> list:
    out.mkdir()
    return list(pycolmap.incremental_mapping(db_path, images, out, mapper_options(cfg)).values())


def mapper_options(cfg: PoseConfig):
    """pycolmap.IncrementalPipelineOptions of the protocol: the rig's calibration held fixed, one
    thread, and the global bundle adjustments capped (``ba_global_max_iterations``,
    ``ba_global_max_refinements``): they are most of a long clip's mapping time. No point colours:
    poses do not use them, and with shared features there are no images to read them from."""
    import pycolmap

    options = pycolmap.IncrementalPipelineOptions(
        extract_colors=False,
        min_model_size=cfg.min_model_size,
        random_seed=cfg.seed,
        num_threads=1,
        ba_refine_focal_length=False,
        ba_refine_principal_point=False,
        ba_refine_extra_params=False,
        ba_refine_sensor_from_rig=False,
        ba_global_frames_ratio=cfg.ba_global_frames_ratio,
        ba_global_points_ratio=cfg.ba_global_frames_ratio,
        ba_global_max_num_iterations=cfg.ba_global_max_iterations,
        ba_global_max_refinements=cfg.ba_global_max_refinements,
        ba_local_max_refinements=cfg.ba_local_max_refinements,
    )
    # Assign a whole new mapper-options object: mutating options.mapper in place is not reliable in pycolmap 4.2.
    options.mapper = pycolmap.IncrementalMapperOptions(
        abs_pose_min_num_inliers=cfg.abs_pose_min_num_inliers,
        abs_pose_min_inlier_ratio=cfg.abs_pose_min_inlier_ratio,
        init_min_tri_angle=cfg.init_min_tri_angle_deg,
    )
    return options


def _poses_from_models(models: list, rig: Rig, num_frames: int) -> SfmResult:
    """Poses from the model that registers the most images (one model = one consistent frame)."""
    poses = {c: np.full((num_frames, 4, 4), np.nan) for c in rig.names}
    registered = {c: np.zeros(num_frames, bool) for c in rig.names}
    if models:
        best = max(models, key=lambda r: r.num_reg_images())
        for image in best.images.values():
            if not image.has_pose:
                continue
            cam, frame = image.name.split("/")
            t = int(Path(frame).stem)
            cam_from_world = image.cam_from_world()
            T_cam_from_world = make_T(cam_from_world.rotation.matrix(), cam_from_world.translation)
            poses[cam][t] = invert_T(T_cam_from_world)
            registered[cam][t] = True
    return SfmResult(poses, registered)
