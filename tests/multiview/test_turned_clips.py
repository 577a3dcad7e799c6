"""Turned copies of the simulated clips (yaw_augment.py) and what the eval stage's estimator sees
of them after the pooling stand-in tokenizer: the measuring side of the trajectory-following study."""

from __future__ import annotations

import numpy as np
import pytest
from yaw_augment import (
    decode_bilinear,
    paired_agreement,
    recovered_yaw,
    trajectory_yaw,
    turned_key,
    turned_poses,
    write_turned_cache,
)

from drivewm.clips import iter_clips
from drivewm.geometry import invert_T, yaw_of
from drivewm.multiview.data import MultiViewDataset

pytestmark = pytest.mark.slow  # codes and scores turned copies of every simulated clip


@pytest.fixture(scope="session")
def turned_latents(sim_clip_dir, tmp_path_factory):
    return write_turned_cache(sim_clip_dir, tmp_path_factory.mktemp("turned_latents"), (-0.25, 0.25))


def test_turned_poses_add_the_yaw_and_keep_the_drive(sim_clip_dir):
    clip = next(iter_clips(sim_clip_dir))
    T = clip.T_world_from_ego
    P0 = np.einsum("ij,njk->nik", invert_T(T[0]), T)
    assert np.allclose(turned_poses(T, 0.0, 0.1), P0, atol=1e-9)  # no turn: the logged drive
    P = turned_poses(T, 0.25, 0.1)
    assert np.allclose(P[0], np.eye(4))
    assert yaw_of(P[-1]) == pytest.approx(yaw_of(P0[-1]) + 0.25 * 1.6, abs=1e-6)
    steps = np.linalg.norm(np.diff(P[:, :3, 3], axis=0), axis=1)  # same speed along the new path
    assert np.allclose(steps, np.linalg.norm(np.diff(P0[:, :3, 3], axis=0), axis=1), atol=1e-9)


def test_estimator_tells_left_from_right_turned_copies_after_tokenizer(turned_latents):
    """The eval stage's estimator on bilinear decodes of the 8x-pooled latents of the real turned
    frames ranks the left-turned copy of every clip above its right-turned one (11 of 12 at least;
    measured 12 of 12): at this resolution it can judge a model's samples."""
    ds = MultiViewDataset(turned_latents, None, 16)
    by_key = {ds.cache.rows[i]["key"]: i for i in range(len(ds))}
    pairs = []
    for key, i in by_key.items():
        if key.endswith(turned_key("", 0.25)):
            j = by_key[key.replace(turned_key("", 0.25), turned_key("", -0.25))]
            cam = ds[i].rig.cameras[0]
            pairs.append(
                (
                    trajectory_yaw(ds[i].trajectory),
                    trajectory_yaw(ds[j].trajectory),
                    recovered_yaw(decode_bilinear(ds.cache[i].latents[0]), cam),
                    recovered_yaw(decode_bilinear(ds.cache[j].latents[0]), cam),
                )
            )
    assert len(pairs) == 12
    assert paired_agreement(pairs) >= 11, pairs
