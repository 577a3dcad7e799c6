"""Paired samples: clips matched by pair_id across conditions; unmatched clips have no partner."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from drivewm.clips.format import ClipMeta
from drivewm.clips.latents import write_latent_clip, write_latent_index
from drivewm.errors import DrivewmError
from drivewm.geometry import load_rig
from drivewm.transfer.data import PairDataset, clip_pairs
from drivewm.transfer.retarget import TargetCondition

RIG = load_rig("front3").scaled(160, 96).to_dict()


def _meta(key: str, pair_id: str, weather: str, time_of_day: str = "day") -> ClipMeta:
    tags = {"weather": weather, "time_of_day": time_of_day, "road_type": "highway", "manoeuvre": "straight"}
    return ClipMeta(key, "log", 0, 10.0, [i * 100_000_000 for i in range(17)], RIG, "c", {}, tags, pair_id=pair_id)


def _cache(tmp_path, metas: list[ClipMeta]):
    rows = []
    for i, meta in enumerate(metas):
        z = torch.full((3, 2, 5, 2, 3), float(i))  # clip i's latents are all i: easy to follow
        rows.append(write_latent_clip(tmp_path, meta, z, np.tile(np.eye(4), (17, 1, 1))))
    write_latent_index(tmp_path, {"path": None, "latent_mean": [0.0, 0.0], "latent_std": [1.0, 1.0]}, rows)
    return tmp_path


METAS = [
    _meta("a_clear", "d1-t0", "clear"),
    _meta("a_snow", "d1-t0", "snow"),
    _meta("a_night", "d1-t0", "clear", "night"),
    _meta("b_clear", "d1-t17", "clear"),  # its snow window was dropped by a filter: no partner
    _meta("c_real", "", "unknown", "unknown"),  # imported video: no pair id, no condition
    _meta("d_snow", "d2-t0", "snow"),
    _meta("d_snow_again", "d2-t0", "snow"),  # the same condition twice is no pair
]


def test_clip_pairs_match_by_id_and_condition() -> None:
    assert clip_pairs(METAS) == [(0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)]
    assert clip_pairs(METAS, [TargetCondition("snow")]) == [(0, 1), (2, 1)]


def test_pair_dataset_samples(tmp_path) -> None:
    data = PairDataset(_cache(tmp_path, METAS), sigma_data=0.5, targets=[TargetCondition("snow")])
    assert len(data) == 2 * 3  # two pairs x three cameras
    s = data[4]  # pair (2 -> 1), view 1
    assert torch.allclose(s.source, torch.full((2, 5, 2, 3), 2 * 0.5)) and torch.allclose(
        s.target, torch.full((2, 5, 2, 3), 0.5)
    )
    assert s.condition == TargetCondition("snow", "day")
    assert "snow" in s.caption and "night" not in s.caption and s.caption.startswith("The front camera view")
    assert data.latent_shape == (2, 5, 2, 3) and data.num_frames == 17


def test_no_pairs_is_a_clear_error(tmp_path) -> None:
    with pytest.raises(DrivewmError, match="no clip pairs"):
        PairDataset(_cache(tmp_path, METAS[3:5]))


def test_a_repeated_target_is_drawn_more_often_and_the_others_stay(tmp_path) -> None:
    """target_repeat {clear:night: 3}: the two pairs into night appear three times each, the four
    others once, so night is 6 of 10 pairs' samples and every target still trains."""
    night = TargetCondition("clear", "night")
    data = PairDataset(_cache(tmp_path, METAS), repeat={night: 3})
    conditions = [data[i].condition for i in range(0, len(data), 3)]  # one view of each repeated pair
    assert len(data) == (2 * 3 + 4) * 3  # (night pairs x 3 + the others) x three cameras
    assert conditions.count(night) == 6 and conditions.count(TargetCondition("snow", "day")) == 2
    assert conditions.count(TargetCondition("clear", "day")) == 2


def test_target_repeat_is_checked() -> None:
    from drivewm.transfer.train import RECIPES

    cfg = RECIPES.resolve("debug", overrides=["target_repeat={clear:night: 3}"])
    assert cfg.target_repeats() == {TargetCondition("clear", "night"): 3}
    for bad, message in (("{clear:night: 0}", "whole numbers >= 1"), ("{clear:nite: 2}", "clear:nite")):
        with pytest.raises(DrivewmError, match=message):
            RECIPES.resolve("debug", overrides=[f"target_repeat={bad}"])
