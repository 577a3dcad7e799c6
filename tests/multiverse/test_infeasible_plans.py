"""A manoeuvre the simulator cannot carry out at the branch point (a lane change with no lane on that
side) is not turned into another plan silently: its future is simulated with the ego keeping its lane,
recorded as infeasible in ranking.json and the report, and ranked after every feasible future."""

from __future__ import annotations

import numpy as np

from drivewm.logs.reader import read_log
from drivewm.multiverse import MultiverseConfig, run_multiverse


def test_a_lane_change_with_no_lane_there_is_infeasible_and_ranks_last(tmp_path) -> None:
    """highway-env's merge scenario starts the ego on the right lane of its two-lane road: ``right`` has no
    lane to go to. It drives exactly as ``keep`` (so it scores as well) yet ranks after ``keep`` and ``left``."""
    cfg = MultiverseConfig(
        scenario="merge",
        at_s=0.5,
        horizon_s=1.0,
        past_s=0.2,
        plans=["right", "keep", "left"],
        rig="front1",
        width=64,
        height=32,
        eval_metrics=[],
    )
    ranking = run_multiverse(cfg, tmp_path / "out", progress=False)
    by_plan = {f["plan"]: f for f in ranking["futures"]}
    assert [f["plan"] for f in ranking["futures"]][-1] == "right"
    assert not by_plan["right"]["feasible"] and "no lane to the right" in by_plan["right"]["infeasible"]
    assert by_plan["keep"]["feasible"] and by_plan["left"]["feasible"] and by_plan["left"]["infeasible"] is None
    assert by_plan["right"]["scores"] == by_plan["keep"]["scores"]
    ego = {p: read_log(tmp_path / "out/futures" / p / "drive.mcap").T_world_from_ego for p in cfg.plans}
    assert np.array_equal(ego["right"], ego["keep"])  # it kept its lane
    assert abs(ego["left"][-1, 1, 3] - ego["keep"][-1, 1, 3]) > 0.5  # the feasible one changed lanes
    assert "<td>no: no lane to the right" in (tmp_path / "out/report.html").read_text()
    assert "feasible plans first" in ranking["rule"]["description"]
