"""The ``model`` renderer of the futures: a multi-view world model (``model_type: multiview``, loaded
through drivewm.generate.registry and sampled by its generator) generates each future's cameras.

Ticks are cut into windows of the model's frame count (1 + (latent t - 1) x temporal compression), one
generated frame per tick, each window conditioned on the ego waypoints that follow its first tick (at
the model's spacing) and the prompt. What else a window is generated from depends on the model:

- a model trained with a layout (``multiview.layout``): the window's layout (road users' boxes, the props
  the simulator's renderer would place, road lines; drivewm.layout.build) drawn into the rig. Windows are
  consecutive and independent;
- a model without one (the shipped ``multiview``: text and ego trajectory): Video2World continuation, as
  ``drivewm rollout`` does (drivewm.generate.rollout). The past is generated from the trajectory alone
  for its first window, every later window starts from the last frames generated before it, and every
  future starts from the past's frames at the branch tick, so the futures continue one shared past.
  Road users are not conditioned: the model draws whatever traffic it imagines.

A window that runs past the last tick is padded with ticks extrapolated at the ego's last velocity (road
users kept where they were last) and only its own frames are kept. Window k of every call draws its
noise from seed + k, so futures differ by their conditions, not by their noise; a trajectory model
samples window k of every future in one denoiser batch (:meth:`ModelCameras.futures_frames`). The prompt is the run's,
with the branch's weather and time of day where it names none.
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

#: What each kind of model generates a future from (reports and ranking.json).
CONDITIONING = {"layout": "layout, ego trajectory and prompt", "trajectory": "ego trajectory and prompt"}


def load_world_model(folder: str, device: str = "auto"):
    """The multi-view generator of model folder ``folder`` (drivewm.generate.registry); a one-line
    DrivewmError for any other model family (only multi-view models take a rig and an ego trajectory)."""
    from drivewm.generate.registry import load_generator

    generator = load_generator(folder, device)
    if generator.model_type != "multiview":
        raise DrivewmError(
            f"--model {folder}: a {generator.model_type} model; --renderer model needs a multi-view model "
            "(model_type multiview, e.g. shipped:multiview)"
        )
    return generator


class ModelCameras:
    """The world model generating a branch's cameras window by window (see the module)."""

    name = "model"

    def __init__(self, branch: Branch, generator, prompt: str, seed: int, steps: int, progress: bool = True):
        self.gen, self.seed, self.progress = generator, seed, progress
        self.prompt = model_prompt(prompt, branch.tags)
        self.request = GenerateRequest([self.prompt])
        self.cfg = GenerateConfig(sampling=SamplingConfig(steps=steps, seed=seed))
        self.sampling = self.cfg.sampling.record()
        mv = generator.model.cfg.multiview
        c, t, h, w = generator.model.latent.latent_shape
        sc = generator.tokenizer.config.spatial_compression
        self.num_frames = 1 + (t - 1) * mv.temporal_compression
        self.num_cond = 1 + (max(1, generator.model.cfg.edm.cond_frames) - 1) * mv.temporal_compression
        """Frames a continued window starts from (its first latent frames)."""
        self.rig = branch.rig.scaled(w * sc, h * sc, fit="crop")
        """The branch's cameras at the model's frame size (the size of every generated frame)."""
        self.conditioning = "trajectory" if mv.layout == "none" else "layout"
        self.description = (
            f"a multi-view world model, generating each future from its {CONDITIONING[self.conditioning]}"
        )
        self.past, self._past_video = branch.past, None
        self.windows_sampled = 0
        """Windows generated so far (one sampler run of every camera each; benchmarks)."""
        if self.conditioning == "layout":
            if branch.source != "log" and not branch.road.props:  # the props the sim renderer would draw
                ticks = branch.past + [t for f in branch.futures for t in f]
                place_world_props(branch.sim, SceneRecording(branch.road, ticks, branch.tags))
            self.static, self.road = branch.road.props, thin_road(branch.road.road_lines())

    def frames(self, ticks: list[SceneTick]) -> dict[str, np.ndarray]:
        """uint8 RGB (T, H, W, 3) per camera, one generated frame per tick."""
        if not ticks:
            return {c.name: np.zeros((0, c.height, c.width, 3), np.uint8) for c in self.rig.cameras}
        if self.conditioning == "layout":
            starts = tqdm(
                range(0, len(ticks), self.num_frames), desc="model windows", leave=False, disable=not self.progress
            )
            joined = np.concatenate([self.layout_window(ticks, s, k) for k, s in enumerate(starts)], axis=1)
        elif ticks[0].timestamp_ns <= self.past[-1].timestamp_ns:  # the past (or a part of it)
            first = next(i for i, t in enumerate(self.past) if t.timestamp_ns == ticks[0].timestamp_ns)
            joined = self.past_video()[:, first : first + len(ticks)]
        else:
            return self.futures_frames([ticks])[0]
        return {c: joined[v] for v, c in enumerate(self.rig.names)}

    def futures_frames(self, futures: list[list[SceneTick]]) -> list[dict[str, np.ndarray]]:
        """:meth:`frames` of each future (the ticks after the branch tick). Video2World: every future
        continues the past's frames at the branch tick, window k of every future sampled in one denoiser
        batch (the frames of one call per future, up to float rounding)."""
        if self.conditioning == "layout" or not any(futures):
            return [self.frames(f) for f in futures]
        given = self.past_video()[:, -self.num_cond :]
        videos = self.continued([self.past[-self.num_cond :] + f for f in futures], [given] * len(futures), 0)
        return [{c: video[v, self.num_cond :] for v, c in enumerate(self.rig.names)} for video in videos]

    def past_video(self) -> np.ndarray:
        """The past's frames (V, T, H, W, 3), generated once: its first window from the trajectory alone."""
        if self._past_video is None:
            first = self.sample_windows([self.past], [0], [None], 0)[0]
            self._past_video = self.continued([self.past], [first], 1)[0]
        return self._past_video

    def continued(self, ticks: list[list[SceneTick]], videos: list[np.ndarray], index: int) -> list[np.ndarray]:
        """Each ``videos[i]`` (V, n, H, W, 3), the frames of the first n ticks of ``ticks[i]``, continued
        window after window to the frames (V, T, H, W, 3) of every tick of ``ticks[i]``; window k of every
        clip from seed + ``index`` + k, all clips' window k in one batch."""
        bar = tqdm(desc="model windows", leave=False, disable=not self.progress)
        while todo := [i for i, v in enumerate(videos) if v.shape[1] < len(ticks[i])]:
            starts = [videos[i].shape[1] - self.num_cond for i in todo]
            firsts = [videos[i][:, s:] for i, s in zip(todo, starts)]
            new = self.sample_windows([ticks[i] for i in todo], starts, firsts, index)
            for i, window in zip(todo, new):
                videos[i] = np.concatenate([videos[i], window[:, self.num_cond :]], axis=1)
            index += 1
            bar.update(len(todo))
        bar.close()
        return [v[:, : len(t)] for v, t in zip(videos, ticks)]

    def sample_windows(
        self, ticks: list[list[SceneTick]], starts: list[int], first_frames: list[np.ndarray | None], index: int
    ) -> list[np.ndarray]:
        """The generated frames (V, num_frames, H, W, 3) of each window from ``ticks[i][starts[i]]`` along
        its ego trajectory, continuing ``first_frames[i]`` (None: generated whole), in one denoiser batch
        with noise seed + ``index``."""
        mv = self.gen.model.cfg.multiview
        conds = [
            self.gen.trajectory_conditions(self.rig, window_waypoints(t, s, mv)[0], f)
            for t, s, f in zip(ticks, starts, first_frames)
        ]
        self.windows_sampled += len(conds)
        samples = self.gen.sample_batch(self.prompt, [self.seed + index] * len(conds), conds, self.request, self.cfg)
        return [s.videos for s in samples]

    def layout_window(self, ticks: list[SceneTick], start: int, index: int) -> np.ndarray:
        """The generated frames (V, n, H, W, 3) of ticks [start, start + num_frames) from their layout (n:
        those there are)."""
        window = padded(ticks[start:], self.num_frames)
        poses = np.stack([t.T_world_from_ego for t in window])
        where = f"multiverse model window at {window[0].timestamp_ns} ns"
        layout = layout_from_world(
            np.array([t.timestamp_ns for t in window]), poses, [t.agents for t in window], self.static, self.road,
            where, thin=False,
        )  # fmt: skip
        waypoints, dt_s = window_waypoints(ticks, start, self.gen.model.cfg.multiview)
        cond = self.gen.layout_conditions(self.rig, LayoutSource(where, layout, waypoints, dt_s))
        self.windows_sampled += 1
        sample = self.gen.sample(self.prompt, self.seed + index, cond, self.request, self.cfg)
        return sample.videos[:, : min(self.num_frames, len(ticks) - start)]


def window_waypoints(ticks: list[SceneTick], start: int, mv) -> tuple[np.ndarray, float]:
    """(waypoints (W, 3) m in the ego frame of ``ticks[start]``, their spacing s): the ticks that follow at
    the model's waypoint spacing ``mv.trajectory_dt_s`` (extrapolated past the last tick)."""
    first, second = padded(ticks[start:], 2)
    tick_s = (second.timestamp_ns - first.timestamp_ns) / 1e9
    stride = max(1, int(round(mv.trajectory_dt_s / tick_s)))
    following = np.stack([t.T_world_from_ego for t in padded(ticks[start:], stride * mv.trajectory_waypoints + 1)])
    return waypoints_from_poses(following[::stride], 0, mv.trajectory_waypoints), stride * tick_s


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
