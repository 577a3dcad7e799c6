"""ATE and RPE against evo's own functions (evo.core.metrics), to 1e-9, under each of evo's settings:
alignment (none, -a, -as), delta in frames and in metres, consecutive or all pairs, pairs from the
reference or the estimate. Trajectories are written to and read back from KITTI-style text, so their
rotations are off orthonormal by ~1e-7 as real odometry files are."""

from __future__ import annotations

import copy
import itertools

import numpy as np
import pytest

from drivewm.eval.trajectory_errors import ate, relative_pose_errors
from drivewm.geometry import euler_to_R, make_T

evo_metrics = pytest.importorskip("evo.core.metrics")
from evo.core.units import Unit  # noqa: E402
from evo.tools import file_interface  # noqa: E402


def drive(n: int = 80) -> np.ndarray:
    """A hilly S-bend at ~1.2 m per frame with roll and pitch: T_world_from_ego (n, 4, 4)."""
    s = np.arange(n) * 1.2
    yaw = 0.4 * np.sin(s / 25.0)
    x = np.cumsum(1.2 * np.cos(yaw))
    y = np.cumsum(1.2 * np.sin(yaw))
    z = 1.5 * np.sin(s / 30.0)
    return np.stack(
        [
            make_T(euler_to_R(0.02 * np.sin(si / 7), 0.03 * np.cos(si / 11), yi), [xi, yi2, zi])
            for si, yi, xi, yi2, zi in zip(s, yaw, x, y, z)
        ]
    )


def perturbed(ref: np.ndarray, seed: int = 0) -> np.ndarray:
    """The reference with a drifting rotation and translation noise, in another frame and at 0.4x scale."""
    rng = np.random.default_rng(seed)
    est = ref.copy()
    drift = np.eye(3)
    for i in range(len(est)):
        drift = drift @ euler_to_R(*rng.normal(0, np.radians(0.15), 3))
        est[i, :3, :3] = est[i, :3, :3] @ drift
        est[i, :3, 3] += rng.normal(0, 0.08, 3) + 0.01 * i
    G = make_T(euler_to_R(0.3, -0.2, 1.2), [5.0, -3.0, 2.0])
    est = np.einsum("ij,njk->nik", G, est)
    est[:, :3, 3] *= 0.4
    return est


def write_kitti(path, T: np.ndarray) -> None:
    """KITTI odometry format: the top 3x4 of each pose, row-major, printed with '%e' (7 digits)."""
    np.savetxt(path, T[:, :3, :].reshape(len(T), 12), fmt="%e")


@pytest.fixture(scope="module")
def kitti_pair(tmp_path_factory):
    root = tmp_path_factory.mktemp("kitti")
    write_kitti(root / "ref.txt", drive())
    write_kitti(root / "est.txt", perturbed(drive()))
    ref = file_interface.read_kitti_poses_file(root / "ref.txt")
    est = file_interface.read_kitti_poses_file(root / "est.txt")
    ours = tuple(
        np.stack([np.vstack([r.reshape(3, 4), [0, 0, 0, 1]]) for r in np.loadtxt(root / n)])
        for n in ("ref.txt", "est.txt")
    )
    return ref, est, ours


def evo_aligned(ref, est, alignment: str):
    out = copy.deepcopy(est)
    if alignment != "none":
        out.align(ref, correct_scale=alignment == "sim3")
    return out


def test_text_rotations_are_not_orthonormal(kitti_pair):
    _, _, (ref, _) = kitti_pair
    off = max(np.abs(R @ R.T - np.eye(3)).max() for R in ref[:, :3, :3])
    assert 1e-9 < off < 1e-5  # the case the nearest-rotation angle exists for


@pytest.mark.parametrize("alignment", ["none", "se3", "sim3"])
def test_ate_equals_evo_ape(kitti_pair, alignment):
    ref, est, (ref_T, est_T) = kitti_pair
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((ref, evo_aligned(ref, est, alignment)))
    ours, _ = ate(est_T, ref_T, alignment=alignment)
    assert ours == pytest.approx(ape.get_statistic(evo_metrics.StatisticsType.rmse), rel=1e-9, abs=1e-12)


SETTINGS = list(itertools.product(["none", "se3", "sim3"], [(1, "frames"), (4, "frames"), (10.0, "m")], [False, True]))


@pytest.mark.parametrize("alignment,delta,all_pairs", SETTINGS)
@pytest.mark.parametrize("pairs_from", ["reference", "estimate"])
def test_rpe_equals_evo_rpe(kitti_pair, alignment, delta, all_pairs, pairs_from):
    ref, est, (ref_T, est_T) = kitti_pair
    value, unit = delta
    _, sim = ate(est_T, ref_T, alignment=alignment)
    ours = relative_pose_errors(est_T, ref_T, value, unit, all_pairs, sim.scale, pairs_from)
    aligned = evo_aligned(ref, est, alignment)
    for relation, stats in (
        (evo_metrics.PoseRelation.translation_part, (ours.trans_rmse, ours.trans_mean)),
        (evo_metrics.PoseRelation.rotation_angle_deg, (ours.rot_rmse, ours.rot_mean)),
    ):
        rpe = evo_metrics.RPE(
            relation,
            value,
            Unit.frames if unit == "frames" else Unit.meters,
            all_pairs=all_pairs,
            pairs_from_reference=pairs_from == "reference",
        )
        rpe.process_data((ref, aligned))
        assert len(rpe.error) == len(ours.pairs) >= 3
        theirs = (
            rpe.get_statistic(evo_metrics.StatisticsType.rmse),
            rpe.get_statistic(evo_metrics.StatisticsType.mean),
        )
        np.testing.assert_allclose(stats, theirs, rtol=1e-9, atol=1e-12, err_msg=str(relation))
