"""Text2World pretraining: a recipe (preset + overrides) and the training task for drivewm.train.

``pretrain_config(preset, overrides)`` builds the typed :class:`PretrainConfig` (what
``drivewm pretrain --dry-run`` prints); ``pretrain(cfg, data_dir, tokenizer_dir, out_dir)`` trains
on the latent cache ``CLIPDIR/latents/NAME`` written by ``drivewm tokenizer encode``.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import torch

from drivewm.clips.latents import LatentCache, find_latent_cache
from drivewm.config import at_least, to_dict
from drivewm.device import resolve_device
from drivewm.diffusion.data import LatentDataset
from drivewm.diffusion.denoiser import EDMConfig, edm_loss, sample_sigma
from drivewm.diffusion.dit_config import DiTConfig, dit_preset, upgrade_saved_config
from drivewm.diffusion.text2world import MODEL_TYPE, LatentInfo, Text2World, Text2WorldConfig, same_statistics
from drivewm.errors import DrivewmError
from drivewm.model_folders import resolve_reference
from drivewm.paths import check_name
from drivewm.recipe import RecipeBook
from drivewm.text import TextConfig
from drivewm.train.checkpoint import read_model_config
from drivewm.train.loop import TrainConfig, TrainTask, train


@dataclasses.dataclass
class DataConfig:
    """Where the latents come from."""

    latents: str | None = None
    """Cache name under CLIPDIR/latents/ (default: the tokenizer folder's name)."""
    frames: int = 0
    """Latent frames per sample, from the first (0 = all). 1 trains on images: the causal tokenizer
    codes frame 0 alone, so latent frame 0 of every clip is an image latent (Cosmos' progressive
    schedule starts with images: many more samples per second, the same network)."""

    def validate(self) -> None:
        at_least(self, 0, "frames")
        if self.latents is not None:
            check_name(self.latents, "latents (cache name)")


@dataclasses.dataclass
class PretrainConfig:
    """A resolved pretraining run (saved in train_state.pt and printed by --dry-run)."""

    preset: str = "debug"
    """The size preset the recipe started from."""
    model: DiTConfig = dataclasses.field(default_factory=DiTConfig)
    """DiT shape; in_channels and text_dim are filled from the data and the text encoder."""
    edm: EDMConfig = dataclasses.field(default_factory=EDMConfig)
    """EDM preconditioning/loss and CFG dropout."""
    text: TextConfig = dataclasses.field(default_factory=TextConfig)
    """Caption encoder."""
    train: TrainConfig = dataclasses.field(default_factory=TrainConfig)
    """Optimisation and run settings."""
    data: DataConfig = dataclasses.field(default_factory=DataConfig)
    """Latent cache selection."""
    sample_steps: int = 12
    """Sampler steps for the sample grids written during training."""
    init: str | None = None
    """Text2World model folder whose DiT weights start the run (warm start: the next stage of a
    progressive schedule, or fine-tuning shipped weights on a fleet's logs); None = random init.
    Its DiT and text settings must equal this run's."""

    def validate(self) -> None:
        at_least(self, 1, "sample_steps")


#: Per-preset training defaults (copy-and-change of the base TrainConfig).
TRAIN_PRESETS: dict[str, dict] = {
    "debug": dict(
        steps=300, batch_size=8, lr=1e-3, warmup_steps=20, ema_decay=0.99, log_every=10, checkpoint_every=100
    ),
    "tiny": dict(steps=4000, batch_size=32, lr=5e-4, warmup_steps=200, ema_decay=0.999, checkpoint_every=250),
    "small": dict(steps=20000, batch_size=32, lr=3e-4, warmup_steps=500, checkpoint_every=1000, sample_every=2000),
    "base": dict(steps=100000, batch_size=64, lr=2e-4, warmup_steps=1000, checkpoint_every=2000, sample_every=5000),
    "large": dict(
        steps=200000,
        batch_size=128,
        lr=1e-4,
        warmup_steps=2000,
        checkpoint_every=2000,
        sample_every=5000,
        activation_checkpointing=True,
        parallel="fsdp",
    ),
    "xl": dict(
        steps=300000,
        batch_size=256,
        lr=1e-4,
        warmup_steps=2000,
        checkpoint_every=2000,
        sample_every=5000,
        activation_checkpointing=True,
        parallel="fsdp",
    ),
}


RECIPES: RecipeBook[PretrainConfig] = RecipeBook(  # no packaged recipes: presets and --set
    "pretrain",
    PretrainConfig,
    {name: {"model": dit_preset(name), "train": TRAIN_PRESETS[name]} for name in TRAIN_PRESETS},
    "debug",
)


def pretrain_config(preset: str, overrides: list[str] | None = None) -> PretrainConfig:
    """The recipe for ``preset`` with ``KEY=VALUE`` overrides (unknown keys/bad values raise DrivewmError)."""
    return RECIPES.resolve(preset, None, overrides or [])


def check_tokenizer(cache: LatentCache, tokenizer_dir: Path) -> None:
    """The cache must have been encoded by ``tokenizer_dir`` (same config and latent statistics)."""
    from drivewm.tokenizer.model import MODEL_TYPE as TOKENIZER

    info = read_model_config(tokenizer_dir, TOKENIZER)
    recorded = cache.tokenizer
    same_config = "config" not in recorded or info.get("config") == recorded["config"]
    same_stats = all(same_statistics(info.get(k), recorded.get(k)) for k in ("latent_mean", "latent_std"))
    if not same_config or not same_stats:
        raise DrivewmError(
            f"{cache.dir}: latents were encoded by another tokenizer ({cache.tokenizer.get('path')}) "
            f"than {tokenizer_dir}"
        )


def encoding_tokenizer(cache: LatentCache) -> tuple[Path | None, str]:
    """The tokenizer folder that encoded ``cache`` (recorded by ``drivewm tokenizer encode``), for a run given
    no ``--tokenizer``: the model then decodes its samples with it (checked like a given one); and the line
    that says so. None when the cache records none (synthetic latents) or the folder is gone: the model's
    samples are then latent previews, and the line a warning."""
    recorded = cache.tokenizer.get("path")
    reference = cache.tokenizer.get("reference")  # drivewm.model_folders.portable_reference; older caches lack it
    candidates = [resolve_reference(reference, cache.dir)] if reference else []
    candidates += [Path(recorded)] if recorded else []
    for found in candidates:
        if found.is_dir():
            return found, f"pretrain: decoding with {found}, the tokenizer that encoded {cache.dir}"
    where = f"its tokenizer {recorded} is gone" if recorded else "it records no tokenizer"
    return None, (
        f"warning: pretrain: {cache.dir}: {where}; the model's samples will be latent previews, not images "
        "(pass --tokenizer TOKDIR to decode them)"
    )


class Text2WorldTask(TrainTask):
    """drivewm.train.loop.TrainTask for Text2World pretraining on a latent dataset."""

    def __init__(self, cfg: PretrainConfig, dataset: LatentDataset, latent: LatentInfo):
        self.cfg = cfg
        self.dataset = dataset
        self.bundle = Text2World(Text2WorldConfig(cfg.model, cfg.edm, cfg.text), latent)
        self.model = self.bundle.denoiser.train()

    def blocks(self) -> list[torch.nn.Module]:
        return list(self.bundle.dit.blocks)

    def num_samples(self) -> int:
        return len(self.dataset)

    def tokens_per_sample(self) -> int:
        c, t, h, w = self.dataset.latent_shape
        m = self.cfg.model
        return (t // m.patch_t) * (h // m.patch_size) * (w // m.patch_size)

    def loss(self, forward, indices: list[int], seeds: list[int], device: torch.device) -> torch.Tensor:
        samples = [self.dataset[i] for i in indices]
        x0 = torch.stack([s.latents for s in samples]).to(device)  # (B, c, t, h, w)
        gens = [torch.Generator().manual_seed(s) for s in seeds]
        sigma = torch.cat([sample_sigma(1, self.cfg.edm, g) for g in gens])  # (B,)
        noise = torch.stack([torch.randn(x0.shape[1:], generator=g) for g in gens]).to(device)
        keep = torch.tensor([float(torch.rand(1, generator=g)) >= self.cfg.edm.text_dropout for g in gens])
        cond = self.bundle.conditioning([s.caption for s in samples])
        cond = dataclasses.replace(cond, fps=torch.tensor([s.fps for s in samples])).to(device)
        return edm_loss(forward, self.cfg.edm, x0, cond, sigma.to(device), noise, keep.to(device))

    def _ema_bundle(self, ema_state: dict[str, torch.Tensor]) -> tuple[Text2World, dict[str, torch.Tensor]]:
        dit_state = {k.removeprefix("backbone."): v for k, v in ema_state.items()}
        with torch.random.fork_rng():  # building a DiT draws initial weights: keep the run's RNG untouched
            bundle = Text2World(self.bundle.cfg, self.bundle.latent)
        bundle.dit.load_state_dict(dit_state)
        return bundle, dit_state

    def save_model(self, ema_state: dict[str, torch.Tensor], out_dir: Path) -> None:
        bundle, dit_state = self._ema_bundle(ema_state)
        bundle.save_pretrained(out_dir, dit_state)

    def sample_grid(self, ema_state: dict[str, torch.Tensor], path: Path) -> None:
        from drivewm.diffusion.generate import decode_latents, write_grid_png

        bundle = self._ema_bundle(ema_state)[0].to(next(self.model.parameters()).device)  # the training device
        prompts = self.dataset.captions()[:4]
        latents = bundle.sample_latents(prompts, list(range(len(prompts))), steps=self.cfg.sample_steps, guidance=3.0)
        write_grid_png(decode_latents(latents, bundle.latent.tokenizer, bundle.device), path, prompts)


def latent_info(dataset: LatentDataset, tokenizer_dir: Path | None) -> LatentInfo:
    first = dataset.cache[0].meta
    rig = first.get_rig().subset(first.cameras[:1]).to_dict()
    return LatentInfo(
        list(dataset.latent_shape),
        dataset.cache.latent_mean.tolist(),
        dataset.cache.latent_std.tolist(),
        dataset.fps,
        str(Path(tokenizer_dir).resolve()) if tokenizer_dir else None,
        rig,
    )


def resolve_for_data(cfg: PretrainConfig, dataset: LatentDataset) -> PretrainConfig:
    """Fill the DiT's in_channels from the latents and text_dim from the text encoder."""
    from drivewm.text import build_text_encoder

    text_dim = cfg.text.dim if cfg.text.kind == "hashed" else build_text_encoder(cfg.text).dim
    c, t, h, w = dataset.latent_shape
    if h % cfg.model.patch_size or w % cfg.model.patch_size or t % cfg.model.patch_t:
        raise DrivewmError(
            f"latents (t, h, w)=({t}, {h}, {w}) do not divide into patches "
            f"{cfg.model.patch_t}x{cfg.model.patch_size}x{cfg.model.patch_size}"
        )
    model = dataclasses.replace(cfg.model, in_channels=c, text_dim=text_dim, cond_mask_channel=cfg.edm.cond_frames > 0)
    return dataclasses.replace(cfg, model=model)


def pretrain(
    cfg: PretrainConfig,
    data_dir: str | Path,
    tokenizer_dir: str | Path | None,
    out_dir: str | Path,
    stop_after: int | None = None,
) -> dict:
    """Train a Text2World model folder into ``out_dir`` (resuming when it holds a train state)."""
    resolve_device(cfg.train.device)  # CUDA asked for where there is none: say so before any work
    check_resume(Path(out_dir), cfg)
    data_dir, tokenizer_dir = Path(data_dir), Path(tokenizer_dir) if tokenizer_dir else None
    cache = find_latent_cache(data_dir, tokenizer_dir, cfg.data.latents)
    dataset = LatentDataset(cache, cfg.edm.sigma_data, cfg.data.frames or None)
    note = ""
    if tokenizer_dir is None:
        tokenizer_dir, note = encoding_tokenizer(dataset.cache)
    if tokenizer_dir is not None:
        check_tokenizer(dataset.cache, tokenizer_dir)
    cfg = resolve_for_data(cfg, dataset)
    torch.manual_seed(cfg.train.seed)  # the DiT's initial weights
    task = Text2WorldTask(cfg, dataset, latent_info(dataset, tokenizer_dir))
    if cfg.init:
        warm_start(task.bundle, Path(cfg.init))
    if note:  # said once the run's config has proved good, so a bad one's error stands alone
        print(note, file=sys.stderr)
    return train(task, cfg.train, out_dir, config_record=to_dict(cfg), stop_after=stop_after)


#: The denoiser settings a network's weights are tied to: its input and output scalings follow from them.
SCALING_KEYS = ("parameterization", "sigma_data")


def same_scalings(what: str, saved_edm: dict, edm: EDMConfig) -> None:
    """Refuse to train on weights saved with other :data:`SCALING_KEYS` than ``edm``'s, naming the --set that
    continues them as they were trained. ``saved_edm``: the ``edm`` section of a saved config."""
    theirs = {k: upgrade_saved_config({"edm": saved_edm})["edm"].get(k) for k in SCALING_KEYS}
    ours = {k: getattr(edm, k) for k in SCALING_KEYS}
    if ours != theirs:
        fix = " ".join(f"--set edm.{k}={v}" for k, v in theirs.items() if ours[k] != v)
        raise DrivewmError(f"{what} was trained with edm {theirs}, this run has {ours}; pass {fix}")


def check_resume(out_dir: Path, cfg: PretrainConfig) -> None:
    """A run folder that already holds a model resumes only with the scalings it was trained with (a run
    started before flow became the default, resumed with the default recipe, would switch mid-run)."""
    if (out_dir / "config.json").is_file():
        saved = read_model_config(out_dir, MODEL_TYPE)["config"].get("edm", {})
        same_scalings(f"{out_dir}: the run in this folder", saved, cfg.edm)


def warm_start(bundle: Text2World, init_dir: Path) -> None:
    """Load the DiT weights of the Text2World folder ``init_dir`` into ``bundle`` (same DiT and text config,
    and the same :data:`SCALING_KEYS` of the denoiser: an EDM network trained on as flow, or the reverse,
    would be a different function from its first step)."""
    parent = Text2World.from_pretrained(init_dir)
    for name in ("dit", "text"):
        ours, theirs = to_dict(getattr(bundle.cfg, name)), to_dict(getattr(parent.cfg, name))
        differ = sorted(k for k in ours if ours[k] != theirs.get(k))
        if differ:
            raise DrivewmError(f"{init_dir}: --init model's {name} config differs from this run's at {differ}")
    same_scalings(f"{init_dir}: --init model", to_dict(parent.cfg.edm), bundle.cfg.edm)
    bundle.dit.load_state_dict(parent.dit.state_dict())
