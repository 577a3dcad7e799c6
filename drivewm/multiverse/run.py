"""``run_multiverse``: branch, render, score and rank every future, then write the report.

Output folder (written whole or not at all, drivewm.atomic)::

    ranking.json                 the futures best first with every score, the rule, the renderer
    config.json                  the run's MultiverseConfig
    report.html, report/*.png    bird's-eye plot, one contact sheet per future
    multiverse.rrd               every future on one Rerun timeline
    futures/PLAN/drive.mcap      the shared past and the future as a drive log (/agents, /road, cameras)
    futures/PLAN/cameras/CAM.mp4 the future's frames per camera (what ``drivewm eval`` scored)
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from tqdm import tqdm

from drivewm.atomic import atomic_path, write_json
from drivewm.config import to_dict
from drivewm.model_folders import SHIPPED_PREFIX, resolve_model_folder
from drivewm.multiverse.branch import Branch
from drivewm.multiverse.cameras import FutureCameras, make_cameras
from drivewm.multiverse.config import MultiverseConfig, RankingConfig
from drivewm.multiverse.model_cameras import load_world_model
from drivewm.multiverse.outputs import encode_frames, write_camera_videos, write_future_log
from drivewm.multiverse.plans import check_plan_names
from drivewm.multiverse.ranking import rank
from drivewm.multiverse.recording import write_recording
from drivewm.multiverse.replay import branch_log
from drivewm.multiverse.report import sheet_frames, write_report
from drivewm.multiverse.scenario import load_scenario
from drivewm.multiverse.scores import score_future
from drivewm.multiverse.simulated import branch_scenario
from drivewm.multiverse.video_scores import video_scores
from drivewm.paths import child_path


def run_multiverse(cfg: MultiverseConfig, out_dir: str | Path, progress: bool = True) -> dict:
    """Every future of ``cfg`` into ``out_dir``; returns the ranking (as in ranking.json)."""
    cfg.validate()
    check_plan_names(cfg.plans)
    generator = load_world_model(resolve_model_folder(cfg.model)) if cfg.renderer == "model" else None
    b = branch_log(cfg) if cfg.log else branch_scenario(cfg, load_scenario(cfg.scenario, cfg))
    cameras = make_cameras(cfg, b, generator, progress)
    b = dataclasses.replace(b, rig=cameras.rig)  # the logs' calibration is the frames' size
    fps = _tick_rate(b)
    with atomic_path(out_dir) as tmp:
        tmp.mkdir(parents=True)
        past_jpeg = encode_frames(cameras.frames(b.past))
        results, sheets, front = [], {}, {}
        todo = zip(b.plans, b.futures, b.infeasible, cameras.futures_frames(b.futures))  # frames made lazily
        bar = tqdm(todo, desc="futures", unit="future", total=len(b.plans), disable=not progress)
        for plan, future, infeasible, frames in bar:
            bar.set_postfix_str(plan.name)
            folder = child_path(tmp / "futures", plan.name, what="plan")
            write_future_log(folder / "drive.mcap", b, plan.name, past_jpeg, future, frames)
            videos = write_camera_videos(folder / "cameras", frames, fps)
            scores = score_future(b.past, future, b.road)
            scores["video"] = video_scores(plan.name, b.rig, fps, future, videos, b.tags, cfg.eval_metrics)
            feasible = {"feasible": not infeasible, "infeasible": infeasible or None}
            results.append({"plan": plan.name, **feasible, "log": f"futures/{plan.name}/drive.mcap", "scores": scores})
            sheets[plan.name] = sheet_frames(frames)
            front[plan.name] = (b.rig.names[0], encode_frames({b.rig.names[0]: frames[b.rig.names[0]]})[b.rig.names[0]])
        ranking = _ranking(cfg, b, cameras, results)
        write_json(tmp / "ranking.json", ranking)
        write_json(tmp / "config.json", to_dict(cfg))
        write_report(tmp, b, ranking, sheets)
        write_recording(tmp / "multiverse.rrd", b, front)
    return ranking


def _tick_rate(b: Branch) -> float:
    """Ticks per second of the branch (a log's median pose interval)."""
    ts = np.array([t.timestamp_ns for t in b.past + b.futures[0]], dtype=np.float64)
    return float(1e9 / np.median(np.diff(ts))) if len(ts) > 1 else b.sim.fps


def _ranking(cfg: MultiverseConfig, b: Branch, cameras: FutureCameras, results: list[dict]) -> dict:
    t0 = b.past[-1].timestamp_ns
    horizon = max((f[-1].timestamp_ns - t0) / 1e9 if f else 0.0 for f in b.futures)
    return {
        "source": b.source,
        "reactive": b.reactive,
        "branch_time_s": (t0 - _first_time(cfg, b)) / 1e9,
        "horizon_s": horizon,
        "renderer": cameras.name,
        "renderer_description": cameras.description,
        "model": _model_name(cfg.model),
        "model_sampling": cameras.sampling,
        "cameras": list(b.rig.names),
        "prompt": cfg.prompt,
        "rule": {**to_dict(cfg.ranking), "description": describe_rule(cfg.ranking)},
        "futures": rank(results, cfg.ranking),
    }


def _model_name(model: str) -> str:
    """How ranking.json names the model: ``shipped:KIND`` as given, any other folder by its absolute path."""
    return model if model.startswith(SHIPPED_PREFIX) or not model else str(Path(model).resolve())


def _first_time(cfg: MultiverseConfig, b: Branch) -> int:
    """The drive's first tick time (ns): 0 for simulated drives, the log's first pose otherwise."""
    return int(round(b.past[-1].timestamp_ns - (cfg.at_s or 0.0) * 1e9)) if b.source == "log" else 0


def describe_rule(rule: RankingConfig) -> str:
    """The rule in one sentence, for reports."""
    parts = {
        "safety": f"safety (collision, then off road, then min TTC < {rule.ttc_floor_s:g} s or gap < "
        f"{rule.gap_floor_m:g} m, then none)",
        "progress": f"progress (distance driven, in {rule.progress_step_m:g} m steps, more first)",
        "comfort": f"comfort (max |jerk| / {rule.jerk_ref_mps3:g} + max |lateral acc.| / {rule.lateral_ref_mps2:g})",
    }
    return (
        "feasible plans first (an infeasible one, e.g. a lane change with no lane on that side, ranks after them), "
        "then sorted by " + ", then ".join(parts[k] for k in rule.order) + "; ties keep the plans' order."
    )
