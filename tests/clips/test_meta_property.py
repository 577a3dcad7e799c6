"""Property tests (hypothesis): whatever a shard's ``KEY.json`` holds, reading it gives clip metadata that
keeps the contract (safe key and camera names, a rig that loads, finite fps) or one line of DrivewmError."""

from __future__ import annotations

import json

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivewm.clips.format import ClipMeta
from drivewm.errors import DrivewmError
from drivewm.geometry import load_rig
from drivewm.paths import NAME_PATTERN

SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
RIG = load_rig("front3").scaled(64, 48, fit="stretch").to_dict()
VALID = ClipMeta(
    "c0", "log", 0, 10.0, [0, 100_000_000, 200_000_000], RIG, trajectory_ego=[[1.5, 0.0, 0.0]], trajectory_dt_s=0.5
).to_json()

#: JSON values of every kind, nested: what a damaged or hand-written KEY.json may hold in any field.
JSON_VALUES = st.recursive(
    st.one_of(
        st.none(),
        st.booleans(),
        st.integers(-(2**70), 2**70),
        st.floats(allow_nan=True, allow_infinity=True),
        st.text(max_size=8),
        st.sampled_from(["../x", "a/b", "a.b", "CAM_FRONT", "", "x" * 200]),
    ),
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=4)),
    max_leaves=12,
)


def _camera_edits() -> st.SearchStrategy:
    """The valid rig with one camera's field replaced, removed, or the camera list itself replaced."""
    cameras = RIG["cameras"]
    field = st.sampled_from(sorted(cameras[0]))
    edit_one = st.tuples(st.integers(0, len(cameras) - 1), field, JSON_VALUES)

    def apply(edit):
        i, name, value = edit
        rig = json.loads(json.dumps(RIG))
        rig["cameras"][i][name] = value
        return rig

    return st.one_of(edit_one.map(apply), JSON_VALUES.map(lambda v: {**RIG, "cameras": v}), JSON_VALUES)


@st.composite
def metadata(draw) -> dict:
    """The valid metadata with a few fields replaced by random JSON (the rig by an edited rig) or removed."""
    data = json.loads(json.dumps(VALID))
    for name in draw(st.lists(st.sampled_from(sorted(VALID)), max_size=3, unique=True)):
        choice = draw(st.integers(0, 2))
        if choice == 0:
            del data[name]
        else:
            data[name] = draw(_camera_edits() if name == "rig" else JSON_VALUES)
    return data


@SETTINGS
@given(data=st.one_of(metadata(), JSON_VALUES))
def test_random_clip_metadata_gives_metadata_that_keeps_the_contract_or_one_line(data):
    try:
        meta = ClipMeta.from_json(json.loads(json.dumps(data)), "shard/c0.json")
    except DrivewmError as exc:
        assert "\n" not in str(exc), str(exc)
        return
    assert NAME_PATTERN.fullmatch(meta.key) and all(NAME_PATTERN.fullmatch(c) for c in meta.cameras)
    assert np.isfinite(meta.fps) and meta.fps > 0 and meta.num_frames >= 1
    waypoints = np.asarray(meta.trajectory_ego, dtype=np.float64)  # what multi-view data and eval read
    assert (waypoints.size == 0 or waypoints.shape[1:] == (3,)) and np.isfinite(waypoints).all()
    rig = meta.get_rig()
    assert all(np.isfinite(np.linalg.inv(cam.K)).all() and cam.width > 0 for cam in rig.cameras)
    assert ClipMeta.from_json(json.loads(json.dumps(meta.to_json())), "again") == meta  # it round-trips


def test_the_unedited_metadata_reads_back():
    assert ClipMeta.from_json(json.loads(json.dumps(VALID)), "c0.json").to_json() == VALID
