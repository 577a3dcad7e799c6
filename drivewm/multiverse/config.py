"""MultiverseConfig: where the futures branch, which plans, how they are rendered and ranked."""

from __future__ import annotations

import dataclasses
import math

from drivewm.config import above, at_least, frame_rate, in_range, require
from drivewm.errors import DrivewmError

RENDERERS = ("sim", "model")
#: Longest future (s): minutes of traffic are no longer one manoeuvre's consequence.
MAX_HORIZON_S = 120.0
RANKING_KEYS = ("safety", "progress", "comfort")


@dataclasses.dataclass
class RankingConfig:
    """The ranking rule: futures sort by the keys of ``order``, each lower-is-better, ties kept in plan order.

    - safety: 3 collision, 2 off the road, 1 too close (min TTC < ``ttc_floor_s`` or min gap <
      ``gap_floor_m``), 0 otherwise;
    - progress: minus the distance driven, in steps of ``progress_step_m`` (so comfort decides between
      futures that get about as far);
    - comfort: max |jerk| / ``jerk_ref_mps3`` + max |lateral acceleration| / ``lateral_ref_mps2``.
    """

    order: list[str] = dataclasses.field(default_factory=lambda: list(RANKING_KEYS))
    """Keys in order of importance, a permutation of a subset of safety, progress, comfort."""
    ttc_floor_s: float = 1.5
    """A future whose time-to-collision drops below this is unsafe (level 1)."""
    gap_floor_m: float = 0.3
    """A future whose ego comes closer than this to a road user is unsafe (level 1)."""
    progress_step_m: float = 5.0
    """Progress is compared in steps of this many metres."""
    jerk_ref_mps3: float = 2.0
    """Jerk that counts as one unit of discomfort."""
    lateral_ref_mps2: float = 2.0
    """Lateral acceleration that counts as one unit of discomfort."""

    def validate(self) -> None:
        bad = [k for k in self.order if k not in RANKING_KEYS]
        if bad or len(set(self.order)) != len(self.order) or not self.order:
            raise DrivewmError(f"ranking.order {self.order}: use distinct keys of {list(RANKING_KEYS)}")
        above(self, 0, "ttc_floor_s", "progress_step_m", "jerk_ref_mps3", "lateral_ref_mps2")
        at_least(self, 0, "gap_floor_m")


@dataclasses.dataclass
class MultiverseConfig:
    """One ``drivewm multiverse`` run."""

    log: str = ""
    """A recorded drive log (MCAP) to branch from; its road users are replayed (non-reactive)."""
    scenario: str = ""
    """Or a simulator scenario: a name (drivewm.sim.config.ALL_SCENARIOS) or a scenario YAML file
    (drivewm.multiverse.scenario)."""
    at_s: float | None = None
    """Branch time, seconds after the drive's first ego pose (required with ``log``; scenarios: 2 s)."""
    plans: list[str] = dataclasses.field(default_factory=lambda: ["keep", "left", "right", "brake", "accelerate"])
    """Plan names (drivewm.multiverse.plans.MANOEUVRES) or waypoint files, one future each."""
    horizon_s: float = 8.0
    """Length of each future after the branch point (a log's future stops at its end)."""
    past_s: float = 2.0
    """How much of the past each future's log carries before the branch point."""
    prompt: str = ""
    """Conditions to render, e.g. "snow at night" (weather and time-of-day words; the model renderer gets it whole)."""
    renderer: str = "sim"
    """sim: the simulator's renderer; model: the world model ``model`` from each future's layout."""
    model: str = ""
    """Model folder (or ``shipped:multiview``) of ``renderer: model``: a multi-view model, generating each future
    from its ego trajectory, and from its layout where the model was trained with one (multiview.layout)."""
    model_steps: int = 10
    """Sampler steps per generated window of ``renderer: model`` (generate's sampler, Heun with guidance 7;
    generate's default is 35). 10 scores as 35 against the simulator's truth at 0.26x the CPU; 6 breaks
    (docs/results.md, benchmarks/bench_multiverse_steps.py)."""
    rig: str = "nuscenes6"
    """Camera rig of simulated scenarios (a log keeps its own)."""
    width: int = 320
    """Rendered image width (px)."""
    height: int = 192
    """Rendered image height (px)."""
    fps: float = 10.0
    """Ticks per second of simulated scenarios (a log keeps its own)."""
    seed: int = 0
    """Seed of a simulated scenario named on the command line (a scenario file gives its own)."""
    waypoint_dt_s: float = 0.5
    """Spacing of waypoints in a waypoint file without ``times_s``."""
    eval_metrics: list[str] = dataclasses.field(default_factory=lambda: ["cse", "adherence"])
    """``drivewm eval`` metrics scored on each future's cameras (subset of drivewm.eval.config.ALL_METRICS)."""
    ranking: RankingConfig = dataclasses.field(default_factory=RankingConfig)
    """The ranking rule."""

    def validate(self) -> None:
        """Raise DrivewmError naming the bad field."""
        if bool(self.log) == bool(self.scenario):
            raise DrivewmError("multiverse: give exactly one of --log (with --at) and --scenario")
        if self.log and self.at_s is None:
            raise DrivewmError("multiverse: --log needs --at SECONDS (the branch time)")
        if self.renderer not in RENDERERS:
            raise DrivewmError(f"multiverse: renderer {self.renderer!r} is not one of {list(RENDERERS)}")
        if (self.renderer == "model") != bool(self.model):
            raise DrivewmError("multiverse: --renderer model needs --model DIR (a multi-view model), only it")
        at_least(self, 1, "model_steps")
        require(bool(self.plans), "plans", self.plans, "at least one plan")
        above(self, 0, "horizon_s", "waypoint_dt_s")
        require(self.horizon_s <= MAX_HORIZON_S, "horizon_s", self.horizon_s, f"at most {MAX_HORIZON_S:g} s")
        if self.at_s is not None:
            require(math.isfinite(self.at_s), "at_s", self.at_s, "a finite number of seconds")
        at_least(self, 0, "past_s")
        frame_rate(self, "fps")
        in_range(self, "width", 16, 4096)
        in_range(self, "height", 16, 4096)
        from drivewm.eval.config import ALL_METRICS

        bad = [m for m in self.eval_metrics if m not in ALL_METRICS]
        if bad:
            raise DrivewmError(f"multiverse: eval metrics {bad} are not among {list(ALL_METRICS)}")
        self.ranking.validate()
