"""Session fixtures of the eval tests: one synthetic nuscenes6 clip (exact geometry) as an EvalItem;
the CLI golden chain's two small simulated drives as clips."""

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


@pytest.fixture(scope="session")
def small_clip_dir(tmp_path_factory):
    """The CLI golden chain's drives (tests/test_outputs_unchanged.py: highway merge in rain at dusk,
    160x96, seeds 11 and 12, 1.8 s) curated with the ``test`` recipe: two 17-frame clips."""
    from drivewm.curate import curate, load_curate_config
    from drivewm.sim import SimConfig, simulate

    root = tmp_path_factory.mktemp("small")
    fields = dict(source="highway", scenario="merge", weather="rain", time_of_day="dusk", duration_s=1.8)
    for seed in (11, 12):
        simulate(SimConfig(**fields, width=160, height=96, seed=seed), root / "logs" / f"d{seed}.mcap")
    curate(sorted((root / "logs").glob("*.mcap")), root / "clips", load_curate_config("test"), workers=1)
    return root / "clips"
