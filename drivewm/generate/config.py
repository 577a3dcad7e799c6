"""The one typed config of ``drivewm generate`` and ``drivewm rollout``, for every model family.

Resolved like every stage's (drivewm.recipe: ``--recipe``, ``--set``, and a few shortcut flags that
are ``--set`` of one field each, drivewm.generate.commands). Defaults draw the network's own frames:
plain sampling, no post-processing. The post-steps that exist are named in :attr:`GenerateConfig.
post_processing`, opt-in, and recorded in every output's metadata (``"post_processing": [...]``).
"""

from __future__ import annotations

import dataclasses
from typing import Literal

from drivewm.ar.sampling_config import TokenSampling
from drivewm.config import MAX_SEED, at_least, check_guidance_interval, require
from drivewm.recipe import RecipeBook

#: Post-steps a generator may apply after the network's sampling, in the order they run:
#: ``reproject`` (drivewm.generate.reproject: each first pass's first frame warped along the trajectory
#: over a flat world, encoded, noised to ``reproject.sigma`` and refined by the network), ``reshade``
#: (the warped road given the first frame's look at its own distance; with ``reproject``), ``blend``
#: (the first pass's first frame blended where the cameras overlap before the reprojection; with
#: ``reproject``) and ``stitch`` (every decoded frame blended where the cameras overlap).
POST_STEPS = ("reproject", "reshade", "blend", "stitch")


@dataclasses.dataclass
class SamplingConfig:
    """How the network is sampled (drivewm.diffusion.sampling)."""

    steps: int = 35
    """Sampler steps (Karras schedule, rho = 7; per window in a rollout)."""
    sampler: str = "heun"
    """``heun`` (EDM Alg. 1) or ``euler`` (drivewm.diffusion.samplers.SAMPLERS)."""
    guidance: float = 7.0
    """Classifier-free guidance scale on the caption (1 = none)."""
    trajectory_guidance: float = 1.0
    """Multi-view models: weigh the trajectory's effect this many times (1 = plain conditioning; >1 costs 2x)."""
    guidance_interval: list[float] | None = None
    """[lo, hi]: guide only at sigma in (lo, hi] (Kynkaanniemi et al. 2024); None: at every sigma."""
    seed: int = 0
    """Sample i (window i of a rollout) draws its noise from seed + i."""

    def validate(self) -> None:
        at_least(self, 1, "steps")
        at_least(self, 0, "guidance", "trajectory_guidance")
        require(0 <= self.seed <= MAX_SEED, "seed", self.seed, f"in [0, {MAX_SEED}]")
        from drivewm.diffusion.samplers import SAMPLERS

        require(self.sampler in SAMPLERS, "sampler", self.sampler, f"one of {sorted(SAMPLERS)}")
        check_guidance_interval("sampling.guidance_interval", self.guidance_interval)

    def interval(self) -> tuple[float, float] | None:
        """:attr:`guidance_interval` as the sampler takes it."""
        return check_guidance_interval("sampling.guidance_interval", self.guidance_interval)

    def sample_kwargs(self) -> dict:
        """The keyword arguments of ``MultiView.sample_latents`` these settings give (besides ``steps``)."""
        return {
            "guidance": self.guidance,
            "sampler": self.sampler,
            "trajectory_guidance": self.trajectory_guidance,
            "guidance_interval": self.interval(),
        }

    def record(self) -> dict:
        """What a generated clip's metadata keeps of the sampling."""
        return {
            "steps": self.steps,
            "sampler": self.sampler,
            "guidance": self.guidance,
            "trajectory_guidance": self.trajectory_guidance,
            "guidance_interval": list(self.guidance_interval) if self.guidance_interval else None,
        }


@dataclasses.dataclass
class ReprojectConfig:
    """Settings of the ``reproject`` post-step (used only when :attr:`GenerateConfig.post_processing` names it)."""

    sigma: float = 0.1
    """Noise level the warped clip is refined from (SDEdit, Meng et al. 2022)."""
    steps: int = 10
    """Sampler steps of the refinement (the Karras schedule from ``sigma`` down to 0)."""

    def validate(self) -> None:
        require(self.sigma > 0, "reproject.sigma", self.sigma, "> 0")
        at_least(self, 1, "steps")


@dataclasses.dataclass
class RolloutConfig:
    """What only ``drivewm rollout`` reads."""

    windows: int = 2
    """Generated windows; each adds (latent frames - cond_frames) * temporal compression frames."""
    speed_mps: float = 0.0
    """Speed of a named trajectory (0 = the clip's own initial speed), at most 100 m/s."""

    def validate(self) -> None:
        at_least(self, 1, "windows")
        require(0 <= self.speed_mps <= 100, "rollout.speed_mps", self.speed_mps, "in [0, 100] m/s")


@dataclasses.dataclass
class GenerateConfig:
    """Everything a generator reads besides its inputs (prompts, a clip, a model folder, an output folder)."""

    sampling: SamplingConfig = dataclasses.field(default_factory=SamplingConfig)
    """The network's sampling."""
    num_samples: int = 1
    """Samples per prompt."""
    batch_size: int = 4
    """Samples denoised together (Text2World)."""
    device: Literal["auto", "cpu", "cuda"] = "auto"
    """Where to sample (``auto``: CUDA when available)."""
    rig: str | None = None
    """Multi-view: camera rig name or YAML (None: the model's training rig, or a condition clip's)."""
    trajectory: str = "straight"
    """Multi-view: straight|left|right|stop or a waypoint file (N, 3) m in the first ego frame."""
    prompt_template: bool = True
    """Multi-view: rewrite each prompt into the training captions' template (weather, time of day,
    road, traffic, the trajectory's manoeuvre and speed); False samples the prompt as given."""
    layout_clips: int = 0
    """Layout generation: windows generated (``--layout``: the first this many clips, 0 = all; ``--scenario``:
    consecutive windows of the simulated drive, 0 = one)."""
    post_processing: list[str] = dataclasses.field(default_factory=list)
    """Opt-in post-steps by name (:data:`POST_STEPS`); [] = the network's own frames."""
    reproject: ReprojectConfig = dataclasses.field(default_factory=ReprojectConfig)
    """Settings of the ``reproject`` post-step."""
    rollout: RolloutConfig = dataclasses.field(default_factory=RolloutConfig)
    """Settings only rollouts read."""
    tokens: TokenSampling = dataclasses.field(default_factory=TokenSampling)
    """Autoregressive models: temperature, top-k and top-p of each token (drivewm.ar.sampling)."""

    def validate(self) -> None:
        at_least(self, 1, "num_samples", "batch_size")
        at_least(self, 0, "layout_clips")
        unknown = [s for s in self.post_processing if s not in POST_STEPS]
        require(not unknown, "post_processing", self.post_processing, f"a list of {list(POST_STEPS)}")
        require(
            len(set(self.post_processing)) == len(self.post_processing),
            "post_processing",
            self.post_processing,
            "without repeats",
        )
        needs = [
            s for s in ("reshade", "blend") if s in self.post_processing and "reproject" not in self.post_processing
        ]
        require(not needs, "post_processing", self.post_processing, f"with 'reproject' for {needs}")

    def post(self, step: str) -> bool:
        """True when the post-step ``step`` is asked for."""
        return step in self.post_processing

    def record(self) -> dict:
        """What every generated clip's metadata keeps: the sampling and the post-steps applied."""
        steps = [s for s in POST_STEPS if s in self.post_processing]
        record = {**self.sampling.record(), "post_processing": steps}
        if self.post("reproject"):
            record["reproject"] = dataclasses.asdict(self.reproject)
        return record


#: ``drivewm generate`` and ``drivewm rollout``: one preset, the packaged recipes in drivewm/recipes/generate/.
RECIPES: RecipeBook[GenerateConfig] = RecipeBook("generate", GenerateConfig, {"default": {}}, "default", "generate")
