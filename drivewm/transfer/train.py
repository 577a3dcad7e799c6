"""Transfer post-training: the recipe (drivewm.recipe.RecipeBook) and the training task for drivewm.train.

``RECIPES.resolve(preset, recipe, overrides)`` builds the typed :class:`TransferTrainConfig` (what
``drivewm transfer-train --dry-run`` prints); ``train_transfer(cfg, init_dir, data_dir, out_dir)``
initialises the transfer model from the Text2World folder ``init_dir`` (drivewm.transfer.init) and
trains it on the paired clips' latent cache with the shared loop (EMA, resume, parallelism).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import torch

from drivewm.clips.latents import find_latent_cache
from drivewm.config import to_dict
from drivewm.device import resolve_device
from drivewm.diffusion.bundle_task import BundleTask
from drivewm.diffusion.denoiser import edm_loss, sample_sigma
from drivewm.diffusion.pretrain import DataConfig, check_tokenizer
from drivewm.diffusion.text2world import Text2World
from drivewm.errors import DrivewmError
from drivewm.recipe import RecipeBook
from drivewm.sim.paired import parse_conditions
from drivewm.train.checkpoint import read_model_config
from drivewm.train.loop import TrainConfig, train
from drivewm.transfer.config import TransferConfig
from drivewm.transfer.data import PairDataset
from drivewm.transfer.init import from_text2world
from drivewm.transfer.model import Transfer
from drivewm.transfer.retarget import TargetCondition


@dataclasses.dataclass
class TransferTrainConfig:
    """A resolved transfer post-training run (saved in train_state.pt and printed by --dry-run)."""

    preset: str = "debug"
    """The preset the run started from (drivewm.transfer.train.RECIPES)."""
    transfer: TransferConfig = dataclasses.field(default_factory=TransferConfig)
    """How the source clip and the target condition enter the model."""
    p_mean: float | None = 0.0
    """Mean of ln(sigma) in training (EDM P_mean); None keeps the parent's. Transfer samples in few
    steps from noise with the whole layout given by the source, so the high noise levels that set it
    are trained more than for generation (EDM's -1.2 puts 6% of samples above sigma 2, 0.0 puts 28%)."""
    targets: list[str] = dataclasses.field(default_factory=list)
    """Target conditions to train, as WEATHER:TIME; empty = every condition the data pairs."""
    target_repeat: dict[str, int] = dataclasses.field(default_factory=dict)
    """WEATHER:TIME -> n: that target's pairs appear n times in an epoch, every other target once (night
    drawn more often without training on night alone, which forgets the others: docs/transfer.md)."""
    train: TrainConfig = dataclasses.field(default_factory=TrainConfig)
    """Optimisation and run settings; ``batch_size`` counts (pair, view) samples."""
    data: DataConfig = dataclasses.field(default_factory=DataConfig)
    """Latent cache selection."""
    sample_steps: int = 8
    """Sampler steps of the sample grids written during training."""

    def validate(self) -> None:
        if self.targets:
            parse_conditions(self.targets)
        if self.target_repeat:
            parse_conditions(list(self.target_repeat))
            bad = {k: n for k, n in self.target_repeat.items() if not (isinstance(n, int) and n >= 1)}
            if bad:
                raise DrivewmError(f"target_repeat counts must be whole numbers >= 1, got {bad}")
        if self.sample_steps < 1:
            raise DrivewmError("transfer-train: sample_steps must be >= 1")

    def target_conditions(self) -> list[TargetCondition] | None:
        return [TargetCondition(w, t) for w, t in parse_conditions(self.targets)] if self.targets else None

    def target_repeats(self) -> dict[TargetCondition, int]:
        return {TargetCondition(*parse_conditions([k])[0]): n for k, n in self.target_repeat.items()}


#: Named runs (copy-and-change of the dataclass defaults). ``debug`` is what 2 CPU cores post-train
#: in about half an hour on the team's 160x96 clips; the others are for GPUs.
RECIPES = RecipeBook(
    "transfer-train",
    TransferTrainConfig,
    {
        "debug": {
            "train": dict(
                steps=600, batch_size=8, lr=5e-4, warmup_steps=20, ema_decay=0.99, log_every=10, checkpoint_every=100
            )
        },
        "small": {
            "train": dict(
                steps=10000, batch_size=32, lr=2e-4, warmup_steps=500, checkpoint_every=1000, sample_every=2000
            )
        },
        "base": {
            "train": dict(
                steps=30000,
                batch_size=64,
                lr=1e-4,
                warmup_steps=1000,
                checkpoint_every=2000,
                sample_every=5000,
                activation_checkpointing=True,
            )
        },
    },
    "debug",
)


class TransferTask(BundleTask):
    """The training task of transfer post-training: a :class:`Transfer` on a :class:`PairDataset`."""

    cfg: TransferTrainConfig
    dataset: PairDataset
    bundle: Transfer

    def tokens_per_sample(self) -> int:
        c, t, h, w = self.dataset.latent_shape
        d = self.bundle.cfg.dit
        return (t // d.patch_t) * (h // d.patch_size) * (w // d.patch_size)

    def loss(self, forward, indices: list[int], seeds: list[int], device: torch.device) -> torch.Tensor:
        """EDM loss on the target latents given the source (every sample keeps its source) and, unless
        dropped for classifier-free guidance, the target caption and fields; sample i draws from seeds[i]."""
        samples = [self.dataset[i] for i in indices]
        x0 = torch.stack([s.target for s in samples]).to(device)  # (B, c, t, h, w)
        gens = [torch.Generator().manual_seed(s) for s in seeds]
        edm = self.bundle.cfg.edm
        sigma = torch.cat([sample_sigma(1, edm, g) for g in gens])  # (B,)
        noise = torch.stack([torch.randn(x0.shape[1:], generator=g) for g in gens]).to(device)
        keep = torch.tensor([float(torch.rand(1, generator=g)) >= self.cfg.transfer.condition_dropout for g in gens])
        source = torch.stack([s.source for s in samples])
        cond = self.bundle.conditioning(source, [s.caption for s in samples], [s.condition for s in samples])
        return edm_loss(forward, edm, x0, cond.to(device), sigma.to(device), noise, keep.to(device))

    def new_bundle(self) -> Transfer:
        return Transfer(self.bundle.cfg, self.bundle.latent, self.bundle.parent)

    def sample_grid(self, ema_state: dict[str, torch.Tensor], path: Path) -> None:
        """Rows: source, transferred, true target, for the first samples of the dataset."""
        from drivewm.diffusion.data import denormalize_latents
        from drivewm.diffusion.generate import decode_latents, write_grid_png

        device = next(self.model.parameters()).device  # the training device
        bundle = self.ema_bundle(ema_state).to(device)
        samples = [self.dataset[i] for i in range(0, len(self.dataset), max(1, len(self.dataset) // 2))][:2]
        stats = (
            torch.tensor(bundle.latent.latent_mean),
            torch.tensor(bundle.latent.latent_std),
            self.dataset.sigma_data,
        )
        source = denormalize_latents(torch.stack([s.source for s in samples]), *stats)
        out = bundle.transfer_latents(
            source,
            [s.caption for s in samples],
            [s.condition for s in samples],
            [0] * len(samples),
            self.cfg.sample_steps,
        )
        target = denormalize_latents(torch.stack([s.target for s in samples]), *stats)
        rows = torch.stack([source, out, target], dim=1).flatten(0, 1)  # (3B, c, t, h, w)
        labels = [f"{kind} {s.condition.name}" for s in samples for kind in ("source, to", "transferred to", "true")]
        write_grid_png(decode_latents(rows, bundle.latent.tokenizer, device), path, labels)


def init_transfer(cfg: TransferTrainConfig, init_dir: str | Path) -> Transfer:
    """The model a run starts from: a Text2World folder gives a new transfer model equal to it
    (drivewm.transfer.init); a transfer folder (say ``shipped:transfer``) is fine-tuned as it is,
    with its own ``transfer`` settings and noise distribution (``cfg.transfer`` and ``cfg.p_mean``
    apply to new models only)."""
    if read_model_config(init_dir, ("text2world", "transfer"))["model_type"] == "transfer":
        return Transfer.from_pretrained(init_dir)
    torch.manual_seed(cfg.train.seed)  # the new parameters' initial weights
    return from_text2world(
        Text2World.from_pretrained(init_dir), cfg.transfer, cfg.p_mean, str(Path(init_dir).resolve())
    )


def train_transfer(
    cfg: TransferTrainConfig,
    init_dir: str | Path,
    data_dir: str | Path,
    out_dir: str | Path,
    stop_after: int | None = None,
) -> dict:
    """Post-train a transfer model folder into ``out_dir`` from the Text2World or transfer folder
    ``init_dir`` (resuming when ``out_dir`` holds a train state). Returns the last metrics row."""
    resolve_device(cfg.train.device)  # CUDA asked for where there is none: say so before any work
    model = init_transfer(cfg, init_dir)
    tokenizer = Path(model.latent.tokenizer) if model.latent.tokenizer else None
    cache = find_latent_cache(Path(data_dir), tokenizer, cfg.data.latents)
    dataset = PairDataset(cache, model.cfg.edm.sigma_data, cfg.target_conditions(), cfg.target_repeats())
    if tokenizer is not None:
        check_tokenizer(dataset.cache, tokenizer)
    if dataset.latent_shape[0] != model.cfg.dit.in_channels:
        raise DrivewmError(
            f"{data_dir}: latents have {dataset.latent_shape[0]} channels, {init_dir} was trained on "
            f"{model.cfg.dit.in_channels}"
        )
    model.latent = dataclasses.replace(model.latent, latent_shape=list(dataset.latent_shape), fps=dataset.fps)
    record = {**to_dict(cfg), "init": str(Path(init_dir).resolve())}
    return train(TransferTask(cfg, dataset, model), cfg.train, out_dir, config_record=record, stop_after=stop_after)
