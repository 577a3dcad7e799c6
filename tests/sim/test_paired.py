"""The same drive in several conditions: identical traffic, ego poses and geometry; paired clips."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drivewm.cli import main
from drivewm.clips import iter_clips, read_manifest
from drivewm.errors import DrivewmError
from drivewm.eval.config import MatchConfig
from drivewm.eval.matching import FrameMatcher
from drivewm.layout import layout_from_recording
from drivewm.layout.clip_layout import FIELDS
from drivewm.logs.reader import read_log
from drivewm.sim import SimConfig
from drivewm.sim.drives import record
from drivewm.sim.paired import drive_id, parse_conditions
from drivewm.sim.props import place_props
from drivewm.sim.recipe import load_recipe


def _agents(rec) -> list:
    return [
        [(a.track_id, tuple(a.center_xyz), a.yaw_rad, tuple(a.size_lwh), a.color_rgb) for a in t.agents]
        for t in rec.ticks
    ]


@pytest.mark.parametrize(
    "source,scenario", [("highway", "roundabout"), pytest.param("sumo", "grid", marks=pytest.mark.slow)]
)
def test_conditions_do_not_change_the_drive(source, scenario) -> None:
    clear = SimConfig(source=source, scenario=scenario, duration_s=0.5, seed=7)
    snow = dataclasses.replace(clear, weather="snow", time_of_day="night")
    a, b = record(clear), record(snow)
    assert np.array_equal(
        np.stack([t.T_world_from_ego for t in a.ticks]), np.stack([t.T_world_from_ego for t in b.ticks])
    )
    assert _agents(a) == _agents(b) and a.ticks[0].agents
    lo, hi = a.ego_xy().min(0) - 50, a.ego_xy().max(0) + 50
    props_a, props_b = (place_props(r.road, lo, hi, 7, source == "sumo") for r in (a, b))
    assert [(p.track_id, tuple(p.center_xyz), p.yaw_rad) for p in props_a] == [
        (p.track_id, tuple(p.center_xyz), p.yaw_rad) for p in props_b
    ]
    assert a.tags["drive_id"] == b.tags["drive_id"] == drive_id(clear)
    assert a.tags["weather"] == "clear" and b.tags["weather"] == "snow"
    layouts = [layout_from_recording(r, c) for r, c in ((a, clear), (b, snow))]  # the same layout to condition on
    assert layouts[0].num_boxes > 0
    assert all(np.array_equal(getattr(layouts[0], f), getattr(layouts[1], f)) for f in FIELDS)
    assert drive_id(dataclasses.replace(clear, seed=8)) != drive_id(clear)
    assert drive_id(dataclasses.replace(clear, duration_s=2.0)) != drive_id(clear)


@pytest.mark.slow
def test_simulate_conditions_renders_pixel_aligned_pairs_and_curation_pairs_them(tmp_path) -> None:
    logs = tmp_path / "logs"
    argv = ["simulate", "--scenario", "highway", "--duration", "1.7", "--width", "160", "--height", "96"]
    assert main([*argv, "--seed", "3", "--conditions", "clear:day,overcast:day,fog", "--out", str(logs)]) == 0
    names = sorted(p.name for p in logs.glob("*.mcap"))
    assert names == [f"highway_highway_{c}_day_s0003.mcap" for c in ("clear", "fog", "overcast")]
    a, b = (read_log(logs / f"highway_highway_{c}_day_s0003.mcap") for c in ("clear", "overcast"))
    assert np.array_equal(a.T_world_from_ego, b.T_world_from_ego)
    assert [[x.track_id for x in boxes] for _, boxes in a.agents] == [
        [x.track_id for x in boxes] for _, boxes in b.agents
    ]
    assert a.scene.tags["drive_id"] == b.scene.tags["drive_id"]
    # same geometry, pixel for pixel: SIFT features of one frame in two conditions sit on the same pixels
    matcher = FrameMatcher(MatchConfig())
    shifts = []
    for cam in a.rig.names:
        m = matcher.match(("a", cam), a.images[cam][8].decode(), ("b", cam), b.images[cam][8].decode())
        shifts += list(np.linalg.norm(m.uv_a - m.uv_b, axis=1))
    assert len(shifts) > 50 and np.median(shifts) < 0.5, (len(shifts), np.median(shifts))

    clips = tmp_path / "clips"
    assert main(["curate", str(logs), "--out", str(clips), "--recipe", "transfer"]) == 0
    by_weather = {c.meta.tags["weather"]: c.meta for c in iter_clips(clips)}
    assert set(by_weather) == {"clear", "overcast", "fog"}
    ids = {m.pair_id for m in by_weather.values()}
    assert ids == {f"{a.scene.tags['drive_id']}-t000000"}
    assert len({m.key for m in by_weather.values()}) == 3
    assert {r["pair_id"] for r in read_manifest(clips)} == ids


def test_recipe_conditions_expand_to_one_drive_per_condition(tmp_path) -> None:
    recipe = tmp_path / "r.yaml"
    recipe.write_text(
        "common: {conditions: [clear:day, snow:night]}\n"
        "drives:\n  - {source: highway, seed: 5, count: 2}\n  - {source: sumo, seed: 9, conditions: [fog]}\n"
    )
    plan = load_recipe(recipe)
    assert [(c.source, c.seed, c.weather, c.time_of_day, n) for c, n in plan] == [
        ("highway", 5, "clear", "day", 2),
        ("highway", 5, "snow", "night", 2),
        ("sumo", 9, "fog", "day", 1),
    ]
    plan = load_recipe("transfer")
    assert len({drive_id(c) for c, _ in plan}) == len({(c.source, c.scenario, c.seed) for c, _ in plan})


@pytest.mark.parametrize("spec", ["snow:noon", "hail", "clear:day,clear:day", ""])
def test_bad_conditions_are_one_clear_error(spec, tmp_path, capsys) -> None:
    with pytest.raises(DrivewmError, match="condition"):
        parse_conditions(spec)
    assert main(["simulate", "--conditions", spec or ",", "--duration", "0.2", "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err.startswith("error: ")
    assert not list(tmp_path.glob("*.mcap"))
