"""Property tests (hypothesis): whatever a ``--trajectory FILE`` holds (.json or .npy), it loads as finite
waypoints within reach, which resample and turn into finite rigid poses, or it is one line of DrivewmError."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from drivewm.errors import DrivewmError
from drivewm.multiview.trajectories import MAX_WAYPOINT_M, load_waypoints, poses_from_waypoints, resolve_trajectory

SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
_FOLDER = tempfile.TemporaryDirectory(prefix="drivewm-waypoints-")

NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-2 * MAX_WAYPOINT_M, 2 * MAX_WAYPOINT_M),
    st.integers(-(2**70), 2**70),
)
#: JSON near the accepted forms: rows of numbers (ragged, wrong width), the dict form, and anything else.
ROWS = st.lists(st.lists(st.one_of(NUMBERS, st.text(max_size=3), st.none(), st.booleans()), max_size=4), max_size=6)
WHOLE_ROWS = st.lists(st.lists(NUMBERS, min_size=3, max_size=3), min_size=1, max_size=6)
JSON_DOCS = st.one_of(
    WHOLE_ROWS,
    ROWS,
    ROWS.map(lambda rows: {"trajectory_ego": rows}),
    st.dictionaries(st.text(max_size=6), ROWS, max_size=2),
    st.recursive(st.one_of(st.none(), NUMBERS, st.text(max_size=4)), lambda inner: st.lists(inner, max_size=3)),
)
ARRAYS = hnp.arrays(
    dtype=st.sampled_from([np.float64, np.float32, np.int64, np.complex64, np.bool_, np.dtype("U2")]),
    shape=hnp.array_shapes(min_dims=0, max_dims=3, max_side=5),
)


def _check(path: Path) -> None:
    try:
        waypoints = load_waypoints(path)
    except DrivewmError as exc:
        assert "\n" not in str(exc), str(exc)
        return
    assert waypoints.ndim == 2 and waypoints.shape[1] == 3 and np.isfinite(waypoints).all()
    assert np.abs(waypoints).max() <= MAX_WAYPOINT_M
    resampled = resolve_trajectory(str(path), 8, 0.5)
    assert resampled.shape == (8, 3) and np.isfinite(resampled).all()
    poses = poses_from_waypoints(resampled, 9, 0.5, 10.0)
    rotations = poses[:, :3, :3]
    assert np.isfinite(poses).all()
    assert np.allclose(rotations @ rotations.transpose(0, 2, 1), np.eye(3), atol=1e-6)


@SETTINGS
@given(doc=JSON_DOCS)
def test_random_json_trajectories_load_as_usable_waypoints_or_one_line(doc):
    path = Path(_FOLDER.name) / "trajectory.json"
    path.write_text(json.dumps(doc))
    _check(path)


@SETTINGS
@given(array=ARRAYS)
def test_random_npy_trajectories_load_as_usable_waypoints_or_one_line(array):
    path = Path(_FOLDER.name) / "trajectory.npy"
    np.save(path, array)
    _check(path)


def test_a_valid_trajectory_loads_as_written():
    path = Path(_FOLDER.name) / "valid.json"
    path.write_text(json.dumps({"trajectory_ego": [[1.5, 0.0, 0.0], [3.0, 0.2, 0.0]]}))
    assert load_waypoints(path).tolist() == [[1.5, 0.0, 0.0], [3.0, 0.2, 0.0]]
