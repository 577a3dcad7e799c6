"""The ``model`` renderer of the futures: a layout-conditioned multi-view world model
(drivewm.generate.multiview, ``multiview.layout`` != none) generates each stretch of ticks from its layout.

Ticks are cut into consecutive windows of the model's frame count (1 + (latent t - 1) x temporal
compression), generated one after another, each from its own first ego pose: the window's layout (road
users' boxes, the props the simulator's renderer would place, road lines; drivewm.layout.build) drawn
into the rig at the model's frame size, and its ego waypoints at the model's spacing. A window shorter
than the model's frame count (the last) is padded with ticks extrapolated at the ego's last velocity
(road users kept where they were last) and only its own frames are kept. Window k of every call draws
its noise from seed + k, so futures differ by their layouts, not by their noise. The prompt is the
run's, with the branch's weather and time of day where it names none. One tick is one generated frame.
"""

from __future__ import annotations

import numpy as np
from tqdm import tqdm

from drivewm.errors import DrivewmError
from drivewm.generate.config import GenerateConfig, SamplingConfig
from drivewm.generate.protocol import GenerateRequest
from drivewm.layout.build import layout_from_world, thin_road
from drivewm.layout.sources import LayoutSource
from drivewm.multiverse.branch import Branch
from drivewm.multiverse.scenario import conditions_from_prompt
from drivewm.multiview.trajectories import waypoints_from_poses
from drivewm.sim.scene import SceneRecording, SceneTick
from drivewm.sim.world import place_world_props


def load_layout_model(folder: str, device: str = "auto"):
    """The multi-view generator of model folder ``folder``; a one-line DrivewmError unless it was trained
    with a layout (only such a model generates a future from its layout)."""
    from drivewm.generate.registry import load_generator

    generator = load_generator(folder, device)
    mv = getattr(getattr(generator, "model", None), "cfg", None)
    if "layout" not in generator.inputs or getattr(getattr(mv, "multiview", None), "layout", "none") == "none":
        raise DrivewmError(
            f"--model {folder}: not a multi-view model trained with a layout (multiview.layout); "
            "--renderer model generates each future from its layout and needs one"
        )
    return generator


class ModelCameras:
    """The world model generating a branch's cameras from each window's layout (see the module)."""

    name = "model"

    def __init__(self, branch: Branch, generator, prompt: str, seed: int, steps: int, progress: bool = True):
        self.gen, self.seed, self.progress = generator, seed, progress
        self.prompt = model_prompt(prompt, branch.tags)
        self.request = GenerateRequest([self.prompt])
        self.cfg = GenerateConfig(sampling=SamplingConfig(steps=steps, seed=seed))
        c, t, h, w = generator.model.latent.latent_shape
        sc = generator.tokenizer.config.spatial_compression
        self.num_frames = 1 + (t - 1) * generator.model.cfg.multiview.temporal_compression
        self.rig = branch.rig.scaled(w * sc, h * sc, fit="crop")
        """The branch's cameras at the model's frame size (the size of every generated frame)."""
        if branch.source != "log" and not branch.road.props:  # the props the sim renderer would draw
            ticks = branch.past + [t for f in branch.futures for t in f]
            place_world_props(branch.sim, SceneRecording(branch.road, ticks, branch.tags))
        self.static, self.road = branch.road.props, thin_road(branch.road.road_lines())

    def frames(self, ticks: list[SceneTick]) -> dict[str, np.ndarray]:
        """uint8 RGB (T, H, W, 3) per camera, one generated frame per tick."""
        if not ticks:
            return {c.name: np.zeros((0, c.height, c.width, 3), np.uint8) for c in self.rig.cameras}
        starts = range(0, len(ticks), self.num_frames)
        starts = tqdm(starts, desc="model windows", leave=False, disable=not self.progress)
        videos = [self.window(ticks, s, k) for k, s in enumerate(starts)]
        joined = np.concatenate(videos, axis=1)  # (V, T, H, W, 3)
        return {c: joined[v] for v, c in enumerate(self.rig.names)}

    def window(self, ticks: list[SceneTick], start: int, index: int) -> np.ndarray:
        """The generated frames (V, n, H, W, 3) of ticks [start, start + num_frames) (n: those there are)."""
        window = padded(ticks[start:], self.num_frames)
        poses = np.stack([t.T_world_from_ego for t in window])
        where = f"multiverse model window at {window[0].timestamp_ns} ns"
        layout = layout_from_world(
            np.array([t.timestamp_ns for t in window]), poses, [t.agents for t in window], self.static, self.road,
            where, thin=False,
        )  # fmt: skip
        mv = self.gen.model.cfg.multiview
        first, second = padded(ticks[start:], 2)
        tick_s = (second.timestamp_ns - first.timestamp_ns) / 1e9
        stride = max(1, int(round(mv.trajectory_dt_s / tick_s)))
        following = np.stack([t.T_world_from_ego for t in padded(ticks[start:], stride * mv.trajectory_waypoints + 1)])
        waypoints = waypoints_from_poses(following[::stride], 0, mv.trajectory_waypoints)
        source = LayoutSource(where, layout, waypoints, stride * tick_s)
        cond = self.gen.layout_conditions(self.rig, source)
        sample = self.gen.sample(self.prompt, self.seed + index, cond, self.request, self.cfg)
        return sample.videos[:, : min(self.num_frames, len(ticks) - start)]


def model_prompt(prompt: str, tags: dict[str, str]) -> str:
    """The run's prompt with the branch's weather and time of day added where it names none, so the model
    draws the conditions the scenario or log has ("" in rain at dusk -> "rain, dusk")."""
    named = conditions_from_prompt(prompt)
    missing = [tags[f] for f in ("weather", "time_of_day") if f not in named and tags.get(f)]
    return ", ".join(p for p in [prompt.strip(), *missing] if p)


def padded(ticks: list[SceneTick], num: int) -> list[SceneTick]:
    """The first ``num`` ticks, followed (when fewer) by ticks one interval apart with the ego moving on at
    its last velocity and yaw and the road users where they were last."""
    if not ticks:
        raise DrivewmError("multiverse model: no ticks to generate")
    out = list(ticks[:num])
    if len(out) >= num:
        return out
    last = out[-1]
    prev = out[-2] if len(out) > 1 else last
    dt_ns = (last.timestamp_ns - prev.timestamp_ns) or int(1e8)
    step = last.T_world_from_ego[:3, 3] - prev.T_world_from_ego[:3, 3]
    for k in range(1, num - len(out) + 1):
        T = last.T_world_from_ego.copy()
        T[:3, 3] += k * step
        out.append(SceneTick(last.timestamp_ns + k * dt_ns, T, last.agents, last.ego_speed_mps))
    return out
