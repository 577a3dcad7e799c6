"""drivewm multiverse end to end: a simulated scenario (twice: the same ranking and logs) and a recorded
log (replayed road users); every future's log shares the source log's past bit for bit (the source: the
log itself, or the log drivewm simulate writes of the same drive)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from multiverse_logs import EGO_SPEED_MPS, T0_NS, log_agents, write_test_log

from drivewm.logs.reader import read_log
from drivewm.multiverse import MultiverseConfig, run_multiverse
from drivewm.multiverse.ranking import sort_key
from drivewm.multiverse.scenario import load_scenario
from drivewm.sim import simulate

pytestmark = pytest.mark.slow  # simulates, renders and scores several futures


def _agents(boxes) -> list:
    return sorted((b.track_id, b.center_xyz.tolist(), b.size_lwh.tolist(), b.yaw_rad) for b in boxes)


def test_a_scenario_gives_the_same_ranking_and_logs_twice(tmp_path) -> None:
    cfg = MultiverseConfig(
        scenario="highway",
        at_s=0.5,
        horizon_s=1.0,
        past_s=0.3,
        plans=["keep", "left", "brake"],
        prompt="snow at night",
        rig="front3",
        width=64,
        height=32,
        eval_metrics=["cse", "adherence"],
    )
    first = run_multiverse(cfg, tmp_path / "a", progress=False)
    run_multiverse(cfg, tmp_path / "b", progress=False)
    assert (tmp_path / "a/ranking.json").read_bytes() == (tmp_path / "b/ranking.json").read_bytes()
    for plan in cfg.plans:
        a, b = (tmp_path / x / "futures" / plan / "drive.mcap" for x in "ab")
        assert a.read_bytes() == b.read_bytes()
    assert [f["rank"] for f in first["futures"]] == [1, 2, 3] and first["renderer"] == "sim"
    assert first["model_sampling"] is None
    keys = [sort_key(f["scores"], cfg.ranking) for f in first["futures"]]
    assert keys == sorted(keys)  # best first by the rule
    progress = {f["plan"]: f["scores"]["progress_m"] for f in first["futures"]}
    assert progress["brake"] < progress["keep"] - 1.0
    assert "cse" in first["futures"][0]["scores"]["video"] or "status" in first["futures"][0]["scores"]["video"]
    source = read_log(simulate(load_scenario("highway", cfg).sim, tmp_path / "source.mcap", progress=False))
    for plan in cfg.plans:
        log = read_log(tmp_path / "a/futures" / plan / "drive.mcap")
        assert log.scene.tags["weather"] == "snow" and log.scene.tags["time_of_day"] == "night"
        assert len(log.pose_timestamps_ns) == 4 + 10 and len(log.images["CAM_FRONT"]) == 14
        # the past, ticks 2..5 (0.2 .. 0.5 s), as drivewm simulate logs the same drive
        assert np.array_equal(log.pose_timestamps_ns[:4], source.pose_timestamps_ns[2:6])
        assert np.array_equal(log.T_world_from_ego[:4], source.T_world_from_ego[2:6])
        assert [_agents(b) for _, b in log.agents[:4]] == [_agents(b) for _, b in source.agents[2:6]]
    html = (tmp_path / "a/report.html").read_text()
    assert all(f"<td>{p}</td>" in html for p in cfg.plans) and "(drivewm.sim.render)" in html
    assert (tmp_path / "a/report/birds_eye.png").stat().st_size > 10_000
    assert (tmp_path / "a/multiverse.rrd").stat().st_size > 10_000


def test_a_recorded_log_replays_its_road_users(tmp_path) -> None:
    """The parked car stays where the log has it, so keeping the speed runs into it (last); braking stops
    short; a waypoint plan puts the ego where its file says."""
    log_path = write_test_log(tmp_path / "drive.mcap")
    waypoints = tmp_path / "slow.json"
    waypoints.write_text(json.dumps({"trajectory_ego": [[2.0, 0.0, 0.0], [4.0, 0.5, 0.0]], "times_s": [1.0, 2.0]}))
    cfg = MultiverseConfig(
        log=str(log_path),
        at_s=1.0,
        horizon_s=3.0,
        past_s=0.5,
        plans=["keep", "brake", str(waypoints)],
        width=64,
        height=32,
        eval_metrics=[],
    )
    ranking = run_multiverse(cfg, tmp_path / "out", progress=False)
    order = [f["plan"] for f in ranking["futures"]]
    assert order[-1] == "keep" and ranking["source"] == "log" and not ranking["reactive"]
    keep = ranking["futures"][-1]["scores"]
    assert keep["collision_with"]["track_id"] == "parked" and 2.0 < keep["collision_with"]["time_s"] < 3.0
    brake = next(f for f in ranking["futures"] if f["plan"] == "brake")["scores"]
    assert not brake["collision"] and brake["progress_m"] == pytest.approx(EGO_SPEED_MPS**2 / 8.0, abs=0.6)
    source = read_log(log_path)
    for plan in ("keep", "brake", "slow"):
        log = read_log(tmp_path / "out/futures" / plan / "drive.mcap")
        assert np.array_equal(log.pose_timestamps_ns, source.pose_timestamps_ns[5:])  # 0.5 s .. 3.9 s
        assert np.array_equal(log.T_world_from_ego[:6], source.T_world_from_ego[5:11])
        for k, (t, boxes) in enumerate(log.agents):
            assert t == T0_NS + (5 + k) * 100_000_000
            assert _agents(boxes) == _agents(log_agents(5 + k))  # replayed, also after the branch point
    slow = read_log(tmp_path / "out/futures/slow/drive.mcap")
    branch_x = source.T_world_from_ego[10][0, 3]
    assert slow.T_world_from_ego[5 + 10][:2, 3] == pytest.approx([branch_x + 2.0, -1.75])  # 1 s after the branch
    assert slow.T_world_from_ego[5 + 20][:2, 3] == pytest.approx([branch_x + 4.0, -1.25])
