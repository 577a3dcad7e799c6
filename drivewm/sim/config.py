"""SimConfig: what one simulated drive looks like (source, scenario, rig, conditions, timing)."""

from __future__ import annotations

import dataclasses
from typing import Literal

from drivewm.config import above, in_range, require
from drivewm.errors import DrivewmError
from drivewm.logs.types import TIMES_OF_DAY, WEATHERS

HIGHWAY_SCENARIOS = ("highway", "merge", "roundabout", "intersection")
SUMO_SCENARIOS = ("grid", "spider", "random")


@dataclasses.dataclass
class SimConfig:
    """One simulated drive (apis.md, drivewm.sim)."""

    source: Literal["highway", "sumo"] = "highway"
    """Traffic simulator: highway-env or SUMO (libsumo)."""
    scenario: str | None = None
    """highway|merge|roundabout|intersection (highway-env) or grid|spider|random (SUMO); None: the
    source's first."""
    rig: str = "nuscenes6"
    """Camera rig name (multiview/rigs/NAME.yaml) or a rig YAML path."""
    weather: Literal["clear", "overcast", "rain", "snow", "fog"] = "clear"
    """Weather rendered (also written as the scene tag)."""
    time_of_day: Literal["day", "dusk", "night"] = "day"
    """Time of day rendered (also written as the scene tag)."""
    duration_s: float = 10.0
    """Length of the drive in seconds of simulated time."""
    fps: float = 10.0
    """Logged frames (and poses) per second."""
    width: int | None = None
    """Image width in pixels; None: the rig's own size (intrinsics are scaled with the size)."""
    height: int | None = None
    """Image height in pixels; None: the rig's own size."""
    seed: int = 0
    """Seeds the traffic, the world textures and every random effect: same seed, same pixels."""
    traffic_density: Literal["low", "medium", "high"] = "medium"
    """How many other road users the source spawns."""
    jpeg_quality: int = 92
    """JPEG quality of the logged images."""
    max_range_m: float = 150.0
    """Objects and ground farther than this from a camera are not drawn (fog/haze hides the cut)."""

    def __post_init__(self) -> None:
        if self.scenario is None:
            self.scenario = HIGHWAY_SCENARIOS[0] if self.source == "highway" else SUMO_SCENARIOS[0]

    def validate(self) -> None:
        """Raise DrivewmError naming the bad field."""
        known = HIGHWAY_SCENARIOS if self.source == "highway" else SUMO_SCENARIOS
        if self.source not in ("highway", "sumo"):
            raise DrivewmError(f"sim config: source {self.source!r} is not one of ['highway', 'sumo']")
        if self.scenario not in known:
            raise DrivewmError(
                f"sim config: scenario {self.scenario!r} is not one of {list(known)} for source {self.source}"
            )
        for name, value, allowed in (
            ("weather", self.weather, WEATHERS),
            ("time_of_day", self.time_of_day, TIMES_OF_DAY),
            ("traffic_density", self.traffic_density, ("low", "medium", "high")),
        ):
            if value not in allowed:
                raise DrivewmError(f"sim config: {name} {value!r} is not one of {list(allowed)}")
        above(self, 0, "duration_s", "fps", "max_range_m")
        require(self.num_ticks >= 1, "duration_s * fps", self.duration_s * self.fps, ">= 0.5 (at least one frame)")
        in_range(self, "jpeg_quality", 1, 100)
        in_range(self, "seed", 0, 2**31 - 1)  # SUMO takes a 32-bit signed seed
        if (self.width is None) != (self.height is None) or (
            self.width is not None and min(self.width, self.height) < 16
        ):
            raise DrivewmError(
                f"sim config: give both width and height (>= 16 px) or neither, got {self.width}x{self.height}"
            )

    @property
    def num_ticks(self) -> int:
        """Logged frames in the drive (the first at t = 0)."""
        return int(round(self.duration_s * self.fps))

    @property
    def road_type(self) -> str:
        """The scene tag road_type for this scenario."""
        return {"grid": "urban_grid", "spider": "urban_radial", "random": "urban_random"}.get(
            self.scenario, self.scenario
        )
