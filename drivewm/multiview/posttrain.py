"""Multi-view post-training: a recipe (preset + overrides) and the training task for drivewm.train.

``posttrain_config(preset, overrides)`` builds the typed :class:`PosttrainConfig` (printed by
``drivewm posttrain --dry-run``); ``posttrain(cfg, init_dir, data_dir, out_dir)`` initialises the
multi-view model from the Text2World folder ``init_dir`` (drivewm.multiview.init) and trains it on
the clips' latent cache with the shared loop (EMA, resume, activation checkpointing, FSDP2).
"""

from __future__ import annotations

import collections
import dataclasses
import math
from pathlib import Path

import torch

from drivewm.clips.latents import find_latent_cache
from drivewm.config import above, at_least, to_dict
from drivewm.device import resolve_device
from drivewm.diffusion.bundle_task import BundleTask
from drivewm.diffusion.denoiser import edm_loss, sample_sigma
from drivewm.diffusion.pretrain import DataConfig
from drivewm.diffusion.text2world import Text2World
from drivewm.errors import DrivewmError
from drivewm.geometry import load_rig
from drivewm.model_folders import resolve_model_folder
from drivewm.multiview.config import MultiViewConfig, with_layout_control
from drivewm.multiview.data import MultiViewDataset, MultiViewSample
from drivewm.multiview.init import control_copy, from_text2world
from drivewm.multiview.model import MODEL_TYPE as MV_MODEL_TYPE
from drivewm.multiview.model import MultiView, MultiViewConditioning, build_conditioning
from drivewm.multiview.trajectory_probe import is_turning, loss_gap, turning_clips
from drivewm.recipe import RecipeBook
from drivewm.train.checkpoint import load_weights, read_model_config, read_model_type
from drivewm.train.loop import TrainConfig, train


@dataclasses.dataclass
class PosttrainConfig:
    """A resolved post-training run (saved in train_state.pt and printed by --dry-run)."""

    preset: str = "debug"
    """The recipe the run started from (drivewm.multiview.posttrain.POSTTRAIN_PRESETS)."""
    rig: str = ""
    """Cameras to train on, by rig name or YAML path (their names, in order, are picked from every
    clip; the geometry is each clip's own calibration). '' = all cameras of the first clip."""
    multiview: MultiViewConfig = dataclasses.field(default_factory=MultiViewConfig)
    """Cross-view attention, camera and trajectory conditioning."""
    cond_frames: int = 1
    """Video2World: clean first latent frames of every view given on conditioned steps (0 = never)."""
    train: TrainConfig = dataclasses.field(default_factory=TrainConfig)
    """Optimisation and run settings; ``batch_size`` counts clips (each with all V views)."""
    data: DataConfig = dataclasses.field(default_factory=DataConfig)
    """Latent cache selection."""
    sample_steps: int = 12
    """Sampler steps for the sample grids written during training."""
    trajectory_probe_every: int = 250
    """Every this many steps (in the next metrics row), log ``trajectory_loss_gap`` and its t
    statistic: the loss of turning clips under mirrored minus under their own waypoints
    (drivewm.multiview.trajectory_probe; > 0 = the trajectory is followed). 0 = never."""
    trajectory_probe_clips: int = 8
    """Turning clips the probe scores: the first ones of the data whose waypoints turn by more than
    ``trajectory_probe_min_turn_deg``; none there, no probe."""
    trajectory_probe_min_turn_deg: float = 15.0
    turn_repeat: int = 0
    """Rebalance steering: every clip whose waypoints turn by more than ``turn_repeat_min_deg``
    appears 1 + this many times per epoch (as GAIA-1 balances its data over steering). Simulated
    and fleet driving is mostly straight, so a turn is a rare lesson; 0 = each clip once."""
    turn_repeat_min_deg: float = 15.0
    rope_spatial_scale: float | None = None
    """The model's ``dit.rope_spatial_scale`` from this run on (None: the init's). 0.5 takes a model
    trained at 160x96 to 320x192 with its row and column positions interpolated, not extrapolated."""
    layout_lr_scale: float = 10.0
    """Learning-rate multiplier of the layout's new parts (the layout encoder and the ControlNet
    branch, multi-view config ``layout``): they start at zero effect, and AdamW moves a weight by
    about the learning rate a step, so at the whole model's rate they would stay near zero for hundreds
    of steps (ControlNet-style branches are trained faster for this reason)."""
    cache_clips: int = 2048
    """Clips whose latents and conditioning (text, rays, waypoints) stay in memory from one
    epoch to the next, least recently used dropped first (about 0.5 MB a clip of six views at 160x96;
    0 = none). Building them is CPU work on the training thread: measured by
    benchmarks/bench_posttrain_batch.py at batch 32 as long as a whole GPU step."""

    def validate(self) -> None:
        at_least(
            self, 0, "cond_frames", "trajectory_probe_every", "trajectory_probe_min_turn_deg", "turn_repeat",
            "turn_repeat_min_deg", "cache_clips", "layout_lr_scale",
        )  # fmt: skip
        at_least(self, 1, "sample_steps", "trajectory_probe_clips")
        if self.rope_spatial_scale is not None:
            above(self, 0, "rope_spatial_scale")


#: Per-preset training defaults. Batches are clips of V views, so they are V times the tokens of
#: a Text2World batch of the same size; the real-size presets checkpoint activations and shard.
POSTTRAIN_PRESETS: dict[str, dict] = {
    "debug": dict(
        steps=300, batch_size=2, lr=5e-4, warmup_steps=20, ema_decay=0.99, log_every=10, checkpoint_every=100
    ),
    "tiny": dict(steps=2000, batch_size=2, lr=2e-4, warmup_steps=100, ema_decay=0.999, checkpoint_every=250),
    "small": dict(steps=10000, batch_size=8, lr=2e-4, warmup_steps=500, checkpoint_every=1000, sample_every=2000),
    "base": dict(
        steps=30000,
        batch_size=16,
        lr=1e-4,
        warmup_steps=1000,
        checkpoint_every=2000,
        sample_every=5000,
        activation_checkpointing=True,
    ),
    "large": dict(
        steps=50000,
        batch_size=32,
        lr=1e-4,
        warmup_steps=1000,
        checkpoint_every=2000,
        sample_every=5000,
        activation_checkpointing=True,
        parallel="fsdp",
    ),
    "xl": dict(
        steps=50000,
        batch_size=32,
        lr=5e-5,
        warmup_steps=1000,
        checkpoint_every=2000,
        sample_every=5000,
        activation_checkpointing=True,
        parallel="fsdp",
    ),
}


RECIPES: RecipeBook[PosttrainConfig] = RecipeBook(
    "posttrain",
    PosttrainConfig,
    {name: {"train": train} for name, train in POSTTRAIN_PRESETS.items()},
    "debug",
    recipes="posttrain",
)


def posttrain_config(preset: str, overrides: list[str] | None = None) -> PosttrainConfig:
    """The recipe for ``preset`` with ``KEY=VALUE`` overrides (unknown keys/bad values raise DrivewmError)."""
    return RECIPES.resolve(preset, None, overrides or [])


@dataclasses.dataclass(frozen=True)
class PreparedClip:
    """One clip as the loss reads it: what :meth:`MultiViewTask.prepared` builds once and keeps."""

    sample: MultiViewSample
    cond: MultiViewConditioning | None

    def noise(self, generator: torch.Generator) -> torch.Tensor:
        """(V, c, t, h, w) standard normal noise from ``generator``."""
        return torch.randn(self.sample.latents.shape, generator=generator)


class MultiViewTask(BundleTask):
    """The training task of multi-view post-training: a :class:`MultiView` on a :class:`MultiViewDataset`."""

    cfg: PosttrainConfig
    dataset: MultiViewDataset
    bundle: MultiView
    _probe_clips: list[int] | None = None  # the trajectory probe's clips, chosen at its first run
    _epoch: list[int] | None = None  # dataset index of every epoch position (turns repeated)
    _prepared: collections.OrderedDict | None = None  # dataset index -> PreparedClip, least recently used first

    def epoch_order(self) -> list[int]:
        """The dataset index behind each position of an epoch: every clip once, and turning clips
        ``turn_repeat`` more times (a clip without ego motion counts as straight)."""
        if self._epoch is None:
            repeat, min_deg = self.cfg.turn_repeat, self.cfg.turn_repeat_min_deg
            self._epoch = list(range(len(self.dataset)))
            if repeat:
                turning = [i for i in self._epoch if is_turning(self.dataset[i], min_deg)]
                self._epoch += turning * repeat
                print(f"turn_repeat: {len(turning)} of {len(self.dataset)} clips turn by more than {min_deg:g} deg")
        return self._epoch

    def num_samples(self) -> int:
        return len(self.epoch_order())

    def lr_scales(self) -> dict[str, float]:
        if self.bundle.net.layout_encoder is None:
            return {}
        return dict.fromkeys(LAYOUT_PARTS, self.cfg.layout_lr_scale)

    def tokens_per_sample(self) -> int:
        t, h, w = self.bundle.token_grid()
        return len(self.dataset.camera_names) * t * h * w

    def loss(self, forward, indices: list[int], seeds: list[int], device: torch.device) -> torch.Tensor:
        """EDM loss over B clips x V views: one noise level per clip (its views are denoised together),
        caption dropout per view, trajectory dropout per clip, and Video2World on a seeded fraction of
        steps. The Video2World draw uses this rank's first sample seed, so with 0 < video2world_prob < 1
        a run is exactly reproducible (and resumable) at a given world size, but not identical across
        world sizes."""
        clips = [self.prepared(self.epoch_order()[i]) for i in indices]
        samples = [c.sample for c in clips]
        v = samples[0].latents.shape[0]
        x0 = torch.cat([s.latents for s in samples]).to(device)  # (B V, c, t, h, w)
        gens = [torch.Generator().manual_seed(s) for s in seeds]
        sigma = torch.cat([sample_sigma(1, self.bundle.cfg.edm, g).expand(v) for g in gens])  # (B V,)
        noise = torch.cat([c.noise(g) for c, g in zip(clips, gens)]).to(device)
        keep = torch.cat([torch.rand(v, generator=g) >= self.bundle.cfg.edm.text_dropout for g in gens])
        video2world = (
            float(torch.rand(1, generator=torch.Generator().manual_seed(seeds[0])))
            < self.cfg.multiview.video2world_prob
        )
        keep_traj = torch.cat(  # a clip without ego poses has no trajectory to keep
            [
                ((torch.rand(1, generator=g) >= self.cfg.multiview.trajectory_dropout) & s.trajectory_known).expand(v)
                for s, g in zip(samples, gens)
            ]
        )
        edm = dataclasses.replace(self.bundle.cfg.edm, cond_frames=self.cfg.cond_frames if video2world else 0)
        cond = cat_conditioning([c.cond for c in clips])
        cond = cond.drop_trajectory(keep_traj)  # one draw per clip: all its views lose the trajectory together
        if cond.layout_keep is not None:  # drawn only for layout models: other runs keep their random streams
            p = self.cfg.multiview.layout_dropout
            keep_layout = torch.cat([(torch.rand(1, generator=g) >= p).expand(v) for g in gens])
            cond = dataclasses.replace(cond, layout_keep=cond.layout_keep & keep_layout)
        return edm_loss(forward, edm, x0, cond.to(device), sigma.to(device), noise, keep.to(device))

    def prepared(self, index: int) -> PreparedClip:
        """Dataset clip ``index`` with its conditioning and noise warp, from memory when an earlier step
        built them (at most ``cache_clips`` kept). All are pure functions of the clip (the text encoder is
        frozen), and the loss only reads them (cat_conditioning and torch.cat copy), so a cached run equals
        an uncached one."""
        if self._prepared is None:
            self._prepared = collections.OrderedDict()
        if index in self._prepared:
            self._prepared.move_to_end(index)
            return self._prepared[index]
        s = self.dataset[index]
        cond = build_conditioning(self.bundle, s.rig, [s.view_captions], s.trajectory[None], s.fps)
        if self.bundle.cfg.multiview.layout != "none":  # a clip without layout trains as a layout-dropped one
            known = torch.full((s.latents.shape[0],), s.layout is not None)
            layout = s.layout if s.layout is not None else torch.zeros_like(s.latents)
            cond = dataclasses.replace(cond, layout=layout, layout_keep=known)
        item = PreparedClip(s, cond)
        if self.cfg.cache_clips:
            self._prepared[index] = item
            if len(self._prepared) > self.cfg.cache_clips:
                self._prepared.popitem(last=False)
        return item

    def after_step(self, step: int) -> dict[str, float]:
        """The trajectory probe, in the first metrics row at or after each ``trajectory_probe_every``
        steps (every rank runs it: under FSDP its forwards gather the shards)."""
        every, log_every = self.cfg.trajectory_probe_every, self.cfg.train.log_every
        if not every or step % log_every or step // every == (step - log_every) // every:
            return {}
        if self._probe_clips is None:
            self._probe_clips = turning_clips(
                self.dataset, self.cfg.trajectory_probe_clips, self.cfg.trajectory_probe_min_turn_deg
            )
        if not self._probe_clips:  # no turning clip in the data: nothing to tell the turns apart by
            return {}
        gap, t = loss_gap(self.model, self.bundle, self.dataset, self._probe_clips)
        return {"trajectory_loss_gap": gap, **({"trajectory_loss_gap_t": t} if math.isfinite(t) else {})}

    def new_bundle(self) -> MultiView:
        return MultiView(self.bundle.cfg, self.bundle.latent)

    def sample_grid(self, ema_state: dict[str, torch.Tensor], path: Path) -> None:
        from drivewm.diffusion.generate import decode_latents, write_grid_png

        bundle = self.ema_bundle(ema_state).to(next(self.model.parameters()).device)  # the training device
        s = self.dataset[0]
        z = bundle.sample_latents(
            s.rig, [s.view_captions], s.trajectory[None], [0], steps=self.cfg.sample_steps, guidance=3.0
        )
        write_grid_png(decode_latents(z[0], bundle.latent.tokenizer, bundle.device), path, s.rig.names)


def cat_conditioning(conds: list[MultiViewConditioning]) -> MultiViewConditioning:
    """Concatenate per-clip conditionings (same views) along the folded (B V) batch."""
    first = conds[0]
    cat = {
        f: torch.cat([getattr(c, f) for c in conds])
        for f in (
            "text_emb",
            "text_mask",
            "fps",
            "rays",
            "static_rays",
            "trajectory",
            "frame_motion",
            "trajectory_keep",
            "layout",
            "layout_keep",
        )
        if getattr(first, f) is not None
    }
    return dataclasses.replace(first, **cat)


def posttrain(
    cfg: PosttrainConfig, init_dir: str | Path, data_dir: str | Path, out_dir: str | Path, stop_after: int | None = None
) -> dict:
    """Post-train a multi-view model folder into ``out_dir`` from ``init_dir``: a Text2World folder
    (the multi-view parts start at zero effect), or a multi-view folder to fine-tune (e.g. the
    shipped model on a fleet's logs). Resumes when ``out_dir`` holds a train state. Returns the
    last metrics row."""
    init_dir = Path(init_dir)
    record = {**to_dict(cfg), "init": str(init_dir.resolve())}
    task = posttrain_task(cfg, init_dir, data_dir)
    return train(task, cfg.train, out_dir, config_record=record, stop_after=stop_after)


def posttrain_task(cfg: PosttrainConfig, init_dir: str | Path, data_dir: str | Path) -> MultiViewTask:
    """The task :func:`posttrain` trains: the model from ``init_dir`` on the latent cache of ``data_dir``."""
    resolve_device(cfg.train.device)  # CUDA asked for where there is none: say so before any work
    init_dir = Path(init_dir)
    init = MultiView.from_pretrained(init_dir) if read_model_type(init_dir) == MV_MODEL_TYPE else None
    parent = Text2World.from_pretrained(init_dir) if init is None else None
    start = init or parent
    tokenizer = Path(start.latent.tokenizer) if start.latent.tokenizer else None
    if tokenizer is not None:  # said now, not at the last step's samples, which decode with it
        try:
            read_model_config(resolve_model_folder(start.latent.tokenizer))
        except DrivewmError as exc:
            raise DrivewmError(
                f"{init_dir}: its tokenizer {exc} (a copied model folder whose relative tokenizer path no longer "
                "resolves?); put the tokenizer there or set latent.tokenizer in its config.json"
            ) from None
    cameras = load_rig(cfg.rig).names if cfg.rig else None
    cache = find_latent_cache(Path(data_dir), tokenizer, cfg.data.latents)
    dataset = MultiViewDataset(cache, cameras, cfg.multiview.trajectory_waypoints, start.cfg.edm.sigma_data)
    if dataset.latent_shape[0] != start.cfg.dit.in_channels:
        raise DrivewmError(
            f"{data_dir}: latents have {dataset.latent_shape[0]} channels, "
            f"{init_dir} was trained on {start.cfg.dit.in_channels}"
        )
    torch.manual_seed(cfg.train.seed)  # the new parameters' initial weights
    speed = init.cfg.multiview.speed_mps if init is not None else cfg.multiview.speed_mps
    mv = dataclasses.replace(
        cfg.multiview,
        trajectory_dt_s=dataset.trajectory_dt_s,
        speed_mps=round(dataset.median_speed_mps(speed), 2),  # data without ego motion: the init's
        temporal_compression=dataset.temporal_compression,
    )
    model = from_text2world(parent, mv, cfg.cond_frames) if init is None else continue_from(init, mv, init_dir)
    model.latent = dataclasses.replace(
        model.latent, latent_shape=list(dataset.latent_shape), fps=dataset.fps, rig=dataset.rig.to_dict()
    )
    if cfg.rope_spatial_scale is not None:  # the DiT reads its config (this same object) when it builds rotations
        model.cfg.dit.rope_spatial_scale = cfg.rope_spatial_scale
    return MultiViewTask(cfg, dataset, model)


#: The parameters a layout adds (drivewm.multiview.layout_encoder, the DiT's ControlNet branch).
LAYOUT_PARTS = ("layout_encoder.", "denoiser.backbone.control.")
#: Zero-initialised parts a fine-tune may add to a multi-view model trained without them.
ADDABLE = ("motion_encoder.", *LAYOUT_PARTS)


def continue_from(init: MultiView, mv: MultiViewConfig, init_dir: Path) -> MultiView:
    """A multi-view model with ``init``'s weights and this run's multi-view settings (training
    probabilities, the data's trajectory spacing). Parts in :data:`ADDABLE` that ``init`` lacks start
    fresh (zero effect, so the model starts as ``init``); any other structural difference is a
    DrivewmError. A model trained with per-frame motion keeps it, with the rays it was trained with
    (its trained motion encoder is not dropped because this run's config left the default)."""
    if init.cfg.multiview.frame_motion:
        mv = dataclasses.replace(mv, frame_motion=True, moving_camera_rays=init.cfg.multiview.moving_camera_rays)
    if init.cfg.multiview.layout != "none" and mv.layout == "none":  # its trained layout path is kept
        keep = ("layout", "layout_control_depth")
        mv = dataclasses.replace(mv, **{k: getattr(init.cfg.multiview, k) for k in keep})
    model = MultiView(with_layout_control(dataclasses.replace(init.cfg, multiview=mv)), init.latent)
    state = init.net.state_dict()
    added = {k: v for k, v in model.net.state_dict().items() if k.startswith(ADDABLE) and k not in state}
    load_weights(model.net, {**state, **added, **control_copy(state, added)}, init_dir)
    return model
