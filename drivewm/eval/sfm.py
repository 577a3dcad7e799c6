"""Structure from motion on a clip with pycolmap (COLMAP 4): the engine behind pose success and trajectories.

Frames are written as PNG to a scratch folder (``CAM/TTTT.png``), SIFT features are extracted per
camera with that camera's pinhole intrinsics held fixed, frames are matched sequentially in time
(``sequential_overlap`` frames ahead, plus the other cameras of the same and nearby frames when the
rig is known), and COLMAP's incremental mapper reconstructs. With a known rig the cameras are tied
by a COLMAP rig config (``apply_rig_config``: each camera's ``cam_from_rig`` from the extrinsics,
held fixed), so all views of one timestamp register together as one frame. pycolmap is imported
when a reconstruction runs, so evals without pose metrics do not load it.
"""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path

import cv2
import numpy as np

from drivewm.eval.config import PoseConfig
from drivewm.geometry import Rig, invert_T, make_T


@dataclasses.dataclass
class SfmResult:
    """Reconstruction of one clip: ``T_world_from_cam`` per camera (T, 4, 4) in the SfM's own world
    frame and scale (NaN where a frame did not register), and ``registered`` per camera (T,) bool."""

    T_world_from_cam: dict[str, np.ndarray]
    registered: dict[str, np.ndarray]

    @property
    def registered_fraction(self) -> float:
        return float(np.mean(np.concatenate(list(self.registered.values()))))

    @property
    def all_registered(self) -> bool:
        return all(bool(r.all()) for r in self.registered.values())


def run_sfm(videos: dict[str, np.ndarray], rig: Rig, cfg: PoseConfig, rig_aware: bool = True) -> SfmResult:
    """Reconstruct the clip. ``videos``: uint8 RGB (T, H, W, 3) per camera of ``rig`` (rig order)."""
    import pycolmap

    pycolmap.set_random_seed(cfg.seed)
    pycolmap.logging.minloglevel = max(
        pycolmap.logging.minloglevel, 2
    )  # COLMAP's INFO lines would drown the progress bar
    with tempfile.TemporaryDirectory(prefix="drivewm-sfm-") as tmp:
        tmp = Path(tmp)
        images, db_path = tmp / "images", tmp / "database.db"
        _write_frames(videos, images)
        for cam in rig.cameras:
            _extract(pycolmap, db_path, images, cam, len(videos[cam.name]), cfg)
        if rig_aware and len(rig.cameras) > 1:
            _apply_rig(pycolmap, db_path, rig)
        _match(pycolmap, db_path, cfg, rig_aware)
        models = _map(pycolmap, db_path, images, tmp / "sparse", cfg)
    num_frames = len(next(iter(videos.values())))
    return _poses_from_models(models, rig, num_frames)


def _write_frames(videos: dict[str, np.ndarray], images: Path) -> None:
    for cam, frames in videos.items():
        (images / cam).mkdir(parents=True, exist_ok=True)
        for t, frame in enumerate(frames):
            cv2.imwrite(str(images / cam / f"{t:04d}.png"), cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))


def _extract(pycolmap, db_path: Path, images: Path, cam, num_frames: int, cfg: PoseConfig) -> None:
    fx, fy, cx, cy = cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2]
    reader = pycolmap.ImageReaderOptions(camera_model="PINHOLE", camera_params=f"{fx},{fy},{cx},{cy}")
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
    options = pycolmap.IncrementalPipelineOptions(
        min_model_size=cfg.min_model_size,
        random_seed=cfg.seed,
        num_threads=1,
        ba_refine_focal_length=False,
        ba_refine_principal_point=False,
        ba_refine_extra_params=False,
        ba_refine_sensor_from_rig=False,
    )
    # Assign a whole new mapper-options object: mutating options.mapper in place is not reliable in pycolmap 4.2.
    options.mapper = pycolmap.IncrementalMapperOptions(
        abs_pose_min_num_inliers=cfg.abs_pose_min_num_inliers,
        abs_pose_min_inlier_ratio=cfg.abs_pose_min_inlier_ratio,
        init_min_tri_angle=cfg.init_min_tri_angle_deg,
    )
    return list(pycolmap.incremental_mapping(db_path, images, out, options).values())


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
