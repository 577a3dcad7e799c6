"""SimConfig: what one simulated drive looks like (source, scenario, rig, conditions, timing)."""

from __future__ import annotations

import dataclasses

from drivewm.config import MAX_SEED, above, at_least, frame_rate, in_range, require
from drivewm.errors import DrivewmError
from drivewm.logs.types import TIMES_OF_DAY, TRAFFIC_DENSITIES, WEATHERS

#: Traffic source -> its scenarios (the first is the source's default).
SCENARIOS = {
    "highway": ("highway", "merge", "roundabout", "intersection"),  # highway-env
    "sumo": ("grid", "spider", "random"),  # SUMO networks made by netgenerate
}
SOURCES = tuple(SCENARIOS)
ALL_SCENARIOS = tuple(name for names in SCENARIOS.values() for name in names)


@dataclasses.dataclass
class SimConfig:
    """One simulated drive (drivewm.sim)."""

    source: str = "highway"
    """Traffic simulator (:data:`SOURCES`): highway-env or SUMO (libsumo)."""
    scenario: str | None = None
    """A scenario of the source (:data:`SCENARIOS`): highway|merge|roundabout|intersection (highway-env)
    or grid|spider|random (SUMO); None: the source's first."""
    rig: str = "nuscenes6"
    """Camera rig name (drivewm/rigs/NAME.yaml) or a rig YAML path."""
    weather: str = "clear"
    """Weather rendered (also written as the scene tag), one of drivewm.logs.types.WEATHERS."""
    time_of_day: str = "day"
    """Time of day rendered (also written as the scene tag), one of drivewm.logs.types.TIMES_OF_DAY."""
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
    traffic_density: str = "medium"
    """How many other road users the source spawns, one of drivewm.logs.types.TRAFFIC_DENSITIES."""
    jpeg_quality: int = 92
    """JPEG quality of the logged images."""
    max_range_m: float = 150.0
    """Objects and ground farther than this from a camera are not drawn (fog/haze hides the cut)."""
    exposure_stagger_ms: float = 0.0
    """Camera i of the rig exposes at tick + i x this (ms), as rigs that fire cameras in turn (nuScenes:
    ~40 ms over the sweep); each image shows the world at its own exposure time and is logged with
    that time. 0: every camera at the tick. (cameras - 1) x stagger must stay below a tick."""
    labels: bool = False
    """Also log each image's exact label map (road, lane paint, vehicle, building, vegetation, sky, ...:
    drivewm.layout.classes.LABEL_CLASSES) as a lossless PNG on /CAMERA/labels; curation carries it
    into the shards (KEY.CAMERA.labels.npz). An output of the drive, not part of it (drive_id ignores it)."""

    def __post_init__(self) -> None:
        if self.scenario is None and self.source in SCENARIOS:
            self.scenario = SCENARIOS[self.source][0]

    def validate(self) -> None:
        """Raise DrivewmError naming the bad field."""
        for name, value, allowed in (
            ("source", self.source, SOURCES),
            ("weather", self.weather, WEATHERS),
            ("time_of_day", self.time_of_day, TIMES_OF_DAY),
            ("traffic_density", self.traffic_density, TRAFFIC_DENSITIES),
        ):
            if value not in allowed:
                raise DrivewmError(f"sim config: {name} {value!r} is not one of {list(allowed)}")
        if self.scenario not in SCENARIOS[self.source]:
            raise DrivewmError(
                f"sim config: scenario {self.scenario!r} is not one of {list(SCENARIOS[self.source])} "
                f"for source {self.source}"
            )
        at_least(self, 0, "exposure_stagger_ms")
        above(self, 0, "duration_s", "max_range_m")
        frame_rate(self, "fps")
        require(self.num_ticks >= 1, "duration_s * fps", self.duration_s * self.fps, ">= 0.5 (at least one frame)")
        in_range(self, "jpeg_quality", 1, 100)
        in_range(self, "seed", 0, MAX_SEED)  # SUMO takes a 32-bit signed seed
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
    def simulated_ticks(self) -> int:
        """Ticks the traffic simulator records: one past the last logged tick when exposures are
        staggered (the last tick's late exposures interpolate towards it)."""
        return self.num_ticks + (1 if self.exposure_stagger_ms > 0 else 0)

    @property
    def road_type(self) -> str:
        """The scene tag road_type for this scenario."""
        return {"grid": "urban_grid", "spider": "urban_radial", "random": "urban_random"}.get(
            self.scenario, self.scenario
        )
