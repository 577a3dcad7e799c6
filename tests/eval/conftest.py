"""Session fixtures of the eval tests: one synthetic nuscenes6 clip (exact geometry) as an EvalItem."""

from __future__ import annotations

import numpy as np
import pytest

from drivewm.geometry import load_rig


@pytest.fixture(scope="session")
def synth_clip6():
    """A 9-frame nuscenes6 clip of the textured corridor (eval_synth), H.264 encoded, 320x192."""
    from eval_synth import synth_clip

    from drivewm.clips import Clip

    clip = synth_clip(
        load_rig("nuscenes6"), "corridor", num_frames=9, seed=0, tags={"weather": "clear", "time_of_day": "day"}
    )
    return Clip(clip.meta, clip.mp4, clip.T_world_from_ego)  # frames decoded from H.264, as from a shard


@pytest.fixture(scope="session")
def synth_item(synth_clip6):
    """``synth_clip6`` as an EvalItem, videos decoded once."""
    from drivewm.eval.inputs import EvalItem

    m = synth_clip6.meta
    item = EvalItem(
        m.key,
        m.get_rig(),
        m.fps,
        synth_clip6.T_world_from_ego,
        dict(m.tags),
        m.trajectory_ego,
        m.trajectory_dt_s,
        clip=synth_clip6,
    )
    item.videos()
    return item


@pytest.fixture(scope="session")
def synth_videos(synth_item) -> dict[str, np.ndarray]:
    return synth_item.videos()
