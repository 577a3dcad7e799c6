"""The ranking rule (drivewm.multiverse.config.RankingConfig): sort keys per future, then a stable sort."""

from __future__ import annotations

import math

from drivewm.multiverse.config import RankingConfig


def safety_level(scores: dict, rule: RankingConfig) -> int:
    """3 collision, 2 off the road, 1 too close (TTC or gap under the floors), 0 otherwise."""
    if scores["collision"]:
        return 3
    if (scores.get("off_road_fraction") or 0.0) > 0.0:
        return 2
    ttc, gap = scores.get("min_ttc_s"), scores.get("min_gap_m")
    if (ttc is not None and ttc < rule.ttc_floor_s) or (gap is not None and gap < rule.gap_floor_m):
        return 1
    return 0


def discomfort(scores: dict, rule: RankingConfig) -> float:
    """max |jerk| / jerk_ref + max |lateral acceleration| / lateral_ref (0 where not measured)."""
    jerk = scores.get("max_abs_jerk_mps3") or 0.0
    lateral = scores.get("max_abs_lateral_accel_mps2") or 0.0
    return jerk / rule.jerk_ref_mps3 + lateral / rule.lateral_ref_mps2


def sort_key(scores: dict, rule: RankingConfig) -> tuple:
    """Lower is better, in the rule's order of keys."""
    keys = {
        "safety": safety_level(scores, rule),
        "progress": -math.floor(scores["progress_m"] / rule.progress_step_m),
        "comfort": round(discomfort(scores, rule), 6),
    }
    return tuple(keys[k] for k in rule.order)


def rank(futures: list[dict], rule: RankingConfig) -> list[dict]:
    """``futures`` ({"plan": name, "scores": {...}, optional "feasible": bool}) best first, each with its
    ``rank`` (1 = best), ``safety_level`` and ``discomfort``: infeasible plans (the simulator could not carry
    out their manoeuvre) after every feasible one, each group sorted by the rule; ties keep the plans' order."""

    def key(i: int) -> tuple:
        return (not futures[i].get("feasible", True), *sort_key(futures[i]["scores"], rule))

    order = sorted(range(len(futures)), key=key)
    ranked = []
    for r, i in enumerate(order, start=1):
        s = futures[i]["scores"]
        ranked.append(
            {"rank": r, **futures[i], "safety_level": safety_level(s, rule), "discomfort": discomfort(s, rule)}
        )
    return ranked
