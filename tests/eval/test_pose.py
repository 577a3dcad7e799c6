"""Pose-estimation success (pycolmap, rig-aware) and the recovered ego trajectory."""

import numpy as np
import pytest

from drivewm.errors import DrivewmError
from drivewm.eval.config import PoseConfig
from drivewm.eval.sfm import mapper_options, run_sfm
from drivewm.eval.trajectory import ego_from_sfm, estimate_ego_trajectory
from drivewm.eval.trajectory_errors import ate, rpe, tfe

FRONT3 = ["CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT"]


@pytest.fixture(scope="module")
def front_sfm(synth_item, synth_videos):
    rig = synth_item.rig.subset(FRONT3)
    return rig, run_sfm({c: synth_videos[c] for c in FRONT3}, rig, PoseConfig())


@pytest.mark.slow
def test_synthetic_clip_registers_and_trajectory_matches(synth_item, front_sfm):
    rig, sfm = front_sfm
    assert sfm.all_registered and sfm.registered_fraction == 1.0
    ego = ego_from_sfm(sfm, rig)
    assert ego.camera == "CAM_FRONT"
    ref = synth_item.T_world_from_ego
    err, sim = ate(ego.T_world_from_ego, ref)
    trans, rot = rpe(ego.T_world_from_ego, ref, 1, sim.scale)
    follow = tfe(
        ego.T_world_from_ego, synth_item.fps, np.asarray(synth_item.trajectory_ego), synth_item.trajectory_dt_s
    )
    print(
        f"synthetic SfM: ATE {err:.4f} m, RPE {trans:.4f} m / {rot:.4f} deg, TFE {follow:.4f} m, scale {sim.scale:.4f}"
    )
    assert err < 0.05 and trans < 0.05 and rot < 0.2 and follow < 0.05
    assert sim.scale == pytest.approx(1.0, abs=0.05)  # rig-aware: the fixed rig baselines make it metric


@pytest.mark.slow
def test_noise_video_fails_pose_estimation(synth_item):
    rng = np.random.default_rng(0)
    rig = synth_item.rig.subset(FRONT3)
    noise = {c: rng.integers(0, 256, (9, 192, 320, 3), dtype=np.uint8) for c in FRONT3}
    sfm = run_sfm(noise, rig, PoseConfig())
    print("noise video registered fraction", sfm.registered_fraction)
    assert not sfm.all_registered and sfm.registered_fraction < 0.5


@pytest.mark.slow
def test_simulated_clip_registers_fully(sim_clip_dir):
    """First 9 frames of the front three cameras of a simulated clear-weather clip (time budget)."""
    from drivewm.eval.inputs import load_items

    item = next(i for i in load_items(sim_clip_dir) if i.tags.get("weather") == "clear")
    videos = {c: v[:9] for c, v in item.videos().items() if c in FRONT3}
    ego = estimate_ego_trajectory(videos, item.rig)  # frames + rig; estimate_ego_trajectory(clip) also works
    err, _ = ate(ego.T_world_from_ego, item.T_world_from_ego[:9])
    print(item.key, "registered", ego.registered.mean(), "ATE", err)
    assert ego.registered.all()
    assert err < 0.5


@pytest.mark.slow
def test_single_camera_frames_give_trajectory_up_to_scale(synth_item, synth_videos):
    cam = synth_item.rig.camera("CAM_FRONT")
    ego = estimate_ego_trajectory(synth_videos["CAM_FRONT"], cam)
    err, sim = ate(ego.T_world_from_ego, synth_item.T_world_from_ego)
    print(f"monocular CAM_FRONT: registered {ego.registered.mean():.2f}, ATE {err:.4f} m, scale {sim.scale:.3f}")
    assert ego.registered.all() and err < 0.05


@pytest.mark.slow
def test_shared_feature_protocol_registers_the_snow_clip_that_colmap_verification_lost(sim_clip_dir):
    """The protocol's SfM (TSE / CSE's SIFT matches, verified by the benchmark's own F fit) registers
    every image of all six cameras of highway_snow-000017, which COLMAP's verification of the same
    matches left 53% registered; ATE 0.04 m when measured (0.085 m with COLMAP's own features)."""
    from drivewm.eval.inputs import load_items

    cfg = PoseConfig()
    assert (cfg.features, cfg.verify) == ("shared", "drivewm")
    item = next(i for i in load_items(sim_clip_dir) if i.key == "highway_snow-000017")
    sfm = run_sfm(item.videos(), item.rig, cfg)
    ego = ego_from_sfm(sfm, item.rig)
    err, sim = ate(ego.T_world_from_ego, item.T_world_from_ego)
    print(f"{item.key}: registered {sfm.registered_fraction:.3f}, ATE {err:.4f} m, scale {sim.scale:.3f}")
    assert sfm.all_registered
    assert err < 0.1
    assert sim.scale == pytest.approx(1.0, abs=0.1)  # the rig's baselines fix the metric scale


@pytest.mark.slow
def test_real_dashcam_start_registers_every_frame(shared_data):
    """The first 48 frames (1.9 s at 25 fps, forward on a highway) of the real dashcam video at
    960x540: with frame gaps [1, 2] only, 4 of them registered (COLMAP's own features: all 48);
    the protocol's gaps [1, 2, 4, 8] register every frame."""
    from test_degenerate import dashcam_camera

    from drivewm.eval.inputs import load_items
    from drivewm.geometry import Rig

    path = shared_data / "video" / "dashcam_highway" / "solidWhiteRight.mp4"
    item = load_items(path, Rig("dashcam", [dashcam_camera()]))[0]
    videos = {c: v[:48] for c, v in item.videos().items()}
    sfm = run_sfm(videos, item.rig, PoseConfig())
    print(f"dashcam, first 48 frames: registered {sfm.registered_fraction:.3f}")
    assert sfm.all_registered


def test_mapper_options_carry_the_protocol_settings():
    """The protocol's mapper settings reach COLMAP's bundle-adjustment and registration options (pycolmap
    4.2 drops some in-place edits of nested options), and bad values are refused."""
    cfg = PoseConfig(
        ba_global_max_iterations=7, ba_local_max_refinements=3, ba_global_max_refinements=4, abs_pose_min_num_inliers=21
    )
    options = mapper_options(cfg)
    assert options.get_global_bundle_adjustment().ceres.solver_options.max_num_iterations == 7
    assert (options.ba_local_max_refinements, options.ba_global_max_refinements) == (3, 4)
    assert options.get_mapper().abs_pose_min_num_inliers == 21
    assert not (options.ba_refine_focal_length or options.ba_refine_extra_params or options.ba_refine_sensor_from_rig)
    for bad in ({"ba_global_max_iterations": 0}, {"ba_global_max_refinements": 0}):
        with pytest.raises(DrivewmError, match=next(iter(bad))):
            PoseConfig(**bad).validate()


@pytest.mark.slow
def test_capped_global_bundle_adjustment_keeps_the_real_dashcam_poses(shared_data):
    """The first 64 frames of the real dashcam video: the protocol's capped global bundle adjustments
    (``ba_global_max_iterations``) register every frame, and the camera path after a similarity alignment
    lies within 0.5% of its length of the path with COLMAP's 50 iterations (same features and matches)."""
    from test_degenerate import dashcam_camera

    from drivewm.eval.config import MatchConfig
    from drivewm.eval.inputs import load_items
    from drivewm.eval.matching import FrameMatcher
    from drivewm.geometry import Rig

    path = shared_data / "video" / "dashcam_highway" / "solidWhiteRight.mp4"
    item = load_items(path, Rig("dashcam", [dashcam_camera()]))[0]
    videos = {c: v[:64] for c, v in item.videos().items()}
    matcher = FrameMatcher(MatchConfig(), threads=2)
    capped = run_sfm(videos, item.rig, PoseConfig(), matcher=matcher)
    full = run_sfm(videos, item.rig, PoseConfig(ba_global_max_iterations=50), matcher=matcher)
    assert capped.all_registered and full.all_registered
    est, ref = capped.T_world_from_cam["CAM_FRONT"], full.T_world_from_cam["CAM_FRONT"]
    err, _ = ate(est, ref)
    length = np.sum(np.linalg.norm(np.diff(ref[:, :3, 3], axis=0), axis=1))
    print(
        f"dashcam, 64 frames: capped vs full BA {err / length:.5f} of the path; "
        f"seconds {capped.seconds} vs {full.seconds}"
    )
    assert err / length < 0.005
    assert set(capped.seconds) == {"database", "mapping"} and min(capped.seconds.values()) > 0


@pytest.mark.slow
def test_a_frozen_clip_registers_through_the_rig_but_does_not_travel_its_path(sim_clip_dir):
    """Every camera of a simulated clear-weather clip, and the same clip frozen on its first frame.
    The rig's baselines let COLMAP register every image of the frozen copy, so ``pose_success``
    passes it (docs/eval-protocol.md); ``pose_success_path`` does not: the reconstruction stands
    while the logged ego drove, as the generated 320x192 samples' reconstructions did."""
    import dataclasses

    from eval_degrade import frozen

    from drivewm.eval.config import EvalConfig
    from drivewm.eval.inputs import load_items
    from drivewm.eval.suite import evaluate_item

    item = next(i for i in load_items(sim_clip_dir) if i.key == "highway_clear-000000")
    cfg = EvalConfig(metrics=["pose", "traj"])
    real = evaluate_item(item, cfg, threads=2).metrics
    still = dataclasses.replace(item)
    still_videos = frozen(item.videos())
    still.videos = lambda: still_videos
    frozen_metrics = evaluate_item(still, cfg, threads=2).metrics
    print({k: (real.get(k), frozen_metrics.get(k)) for k in ("pose_success", "pose_success_path", "path_ratio")})
    assert real["pose_success"] == 1.0 and real["pose_success_path"] == 1.0
    assert real["path_ratio"] == pytest.approx(1.0, abs=0.02)  # rig-aware: metric without alignment
    assert frozen_metrics["pose_success"] == 1.0  # the pass rate a frozen clip wins
    assert frozen_metrics["pose_success_path"] == 0.0 and frozen_metrics["path_ratio"] < 0.2
