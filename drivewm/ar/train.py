"""AR training: a recipe (preset + overrides) and the next-token task for the shared loop (drivewm.train).

``ar_train(cfg, data_dir, tokenizer_dir, out_dir)`` trains on the latent cache that ``drivewm tokenizer
encode`` wrote with the FSQ tokenizer ``tokenizer_dir`` (drivewm.ar.tokens); the loop brings resume,
the compute budget, torchrun and FSDP2, and bf16 autocast on GPUs.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import torch
import torch.nn.functional as F

from drivewm.ar.config import AR_PRESETS, ARConfig, ar_preset
from drivewm.ar.folder import ARModelConfig, save_ar_folder
from drivewm.ar.model import ARCondition, ARTransformer
from drivewm.ar.order import from_sequence, to_sequence
from drivewm.ar.sampling import sample_tokens
from drivewm.ar.sampling_config import TokenSampling
from drivewm.ar.tokens import TOKENIZER_TYPE, TokenDataset, TokenSample, check_cache_tokenizer, fsq_levels
from drivewm.clips.latents import find_latent_cache
from drivewm.config import at_least, in_range, to_dict
from drivewm.device import resolve_device
from drivewm.errors import DrivewmError
from drivewm.paths import check_name
from drivewm.recipe import RecipeBook
from drivewm.text import TextConfig, TextEncoder, build_text_encoder
from drivewm.train.checkpoint import read_model_config
from drivewm.train.loop import TrainConfig, TrainTask, train

LN2 = 0.6931471805599453


@dataclasses.dataclass
class ARDataConfig:
    """Which tokens."""

    latents: str | None = None
    """Cache name under CLIPDIR/latents/ (default: the tokenizer folder's name)."""
    frames: int = 0
    """Latent frames per sample, from the first (0 = the clips' all); at most model.max_frames."""
    holdout_percent: int = 10
    """Clips held out from training by key hash (drivewm.tokenizer.data.is_holdout: the tokenizer's split)."""

    def validate(self) -> None:
        at_least(self, 0, "frames")
        in_range(self, "holdout_percent", 0, 99)
        if self.latents is not None:
            check_name(self.latents, "latents (cache name)")


@dataclasses.dataclass
class ARTrainConfig:
    """A resolved AR training run (saved in train_state.pt and printed by --dry-run)."""

    preset: str = "debug"
    """The size preset the recipe started from."""
    model: ARConfig = dataclasses.field(default_factory=ARConfig)
    """Transformer shape; vocab_size, grid_hw and text_dim are filled from the data and the text encoder."""
    text: TextConfig = dataclasses.field(default_factory=TextConfig)
    """Caption encoder."""
    train: TrainConfig = dataclasses.field(default_factory=TrainConfig)
    """Optimisation and run settings."""
    data: ARDataConfig = dataclasses.field(default_factory=ARDataConfig)
    """Token cache selection."""


#: Per-preset training defaults (copy-and-change of the base TrainConfig).
TRAIN_PRESETS: dict[str, dict] = {
    "debug": dict(steps=300, batch_size=8, lr=1e-3, warmup_steps=20, ema_decay=0.99, checkpoint_every=100),
    "tiny": dict(steps=4000, batch_size=16, lr=1e-3, warmup_steps=100, ema_decay=0.995, checkpoint_every=250),
    "small": dict(steps=20000, batch_size=32, lr=6e-4, warmup_steps=500, checkpoint_every=1000),
    "base": dict(steps=100000, batch_size=64, lr=3e-4, warmup_steps=1000, checkpoint_every=2000),
    "large": dict(steps=200000, batch_size=128, lr=2e-4, warmup_steps=2000, checkpoint_every=2000, parallel="fsdp"),
    "xl": dict(
        steps=300000,
        batch_size=256,
        lr=1.5e-4,
        warmup_steps=2000,
        checkpoint_every=2000,
        activation_checkpointing=True,
        parallel="fsdp",
    ),
}

RECIPES: RecipeBook[ARTrainConfig] = RecipeBook(
    "ar train",
    ARTrainConfig,
    {name: {"model": ar_preset(name), "train": TRAIN_PRESETS[name]} for name in AR_PRESETS},
    "debug",
)


def batch_of(samples: list[TokenSample], text: TextEncoder, model_cfg: ARConfig) -> tuple[torch.Tensor, ARCondition]:
    """Target sequences (B, t*h*w) in the model's order and their conditions."""
    tokens = to_sequence(torch.stack([s.tokens for s in samples]), model_cfg)
    emb, mask = text.encode([s.caption for s in samples])
    cond = ARCondition(
        emb,
        mask,
        torch.stack([s.rays for s in samples]),
        torch.stack([s.ego for s in samples]),
        torch.tensor([s.fps for s in samples]),
    )
    return tokens, cond


def next_token_loss(forward, tokens: torch.Tensor, cond: ARCondition, start_token: int) -> torch.Tensor:
    """Mean cross-entropy (nats per token) of ``tokens`` (B, n) under the model ``forward``."""
    inputs = torch.cat([torch.full_like(tokens[:, :1], start_token), tokens[:, :-1]], dim=1)
    logits = forward(inputs, cond)  # (B, n, vocab)
    return F.cross_entropy(logits.flatten(0, 1).float(), tokens.flatten())


class ARTask(TrainTask):
    """drivewm.train.loop.TrainTask: next-token prediction on a token dataset."""

    def __init__(self, cfg: ARTrainConfig, dataset: TokenDataset, tokenizer_dir: Path):
        self.cfg = cfg
        self.dataset = dataset
        self.tokenizer_dir = tokenizer_dir
        self.text = build_text_encoder(cfg.text)
        self.model = ARTransformer(cfg.model).train()

    def blocks(self) -> list[torch.nn.Module]:
        return list(self.model.blocks)

    def num_samples(self) -> int:
        return len(self.dataset)

    def tokens_per_sample(self) -> int:
        return self.dataset.frames * self.cfg.model.frame_tokens

    def loss(self, forward, indices: list[int], seeds: list[int], device: torch.device):
        tokens, cond = batch_of([self.dataset[i] for i in indices], self.text, self.cfg.model)
        loss = next_token_loss(forward, tokens.to(device), cond.to(device), self.model.start_token)
        return loss, {"bits_per_token": float(loss.detach()) / LN2}

    def model_config(self) -> ARModelConfig:
        return ARModelConfig(self.cfg.model, self.cfg.text, self.dataset.fps)

    def save_model(self, ema_state: dict[str, torch.Tensor], out_dir: Path) -> None:
        save_ar_folder(out_dir, self.model_config(), ema_state, self.tokenizer_dir)

    def sample_grid(self, ema_state: dict[str, torch.Tensor], path: Path) -> None:
        write_sample_grid(self.model_config(), ema_state, self.tokenizer_dir, self.dataset, path)


def resolve_for_data(cfg: ARTrainConfig, dataset: TokenDataset) -> ARTrainConfig:
    """Fill vocab_size, grid_hw and text_dim; a sample longer than the model's context is refused."""
    text_dim = cfg.text.dim if cfg.text.kind == "hashed" else build_text_encoder(cfg.text).dim
    if dataset.frames > cfg.model.max_frames:
        raise DrivewmError(
            f"ar train: samples of {dataset.frames} latent frames are longer than the model's context of "
            f"{cfg.model.max_frames} (set data.frames or model.max_frames)"
        )
    if cfg.model.layout:
        raise DrivewmError("ar train: model.layout needs layout tokens, which the token cache does not hold yet")
    fields = dict(vocab_size=dataset.vocab_size, grid_hw=list(dataset.grid_hw), text_dim=text_dim)
    return dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, **fields))


def ar_train(
    cfg: ARTrainConfig,
    data_dir: str | Path,
    tokenizer_dir: str | Path,
    out_dir: str | Path,
    stop_after: int | None = None,
) -> dict:
    """Train an AR model folder into ``out_dir`` (resuming when it holds a train state)."""
    resolve_device(cfg.train.device)
    tokenizer_dir = Path(tokenizer_dir)
    fsq_levels(read_model_config(tokenizer_dir, TOKENIZER_TYPE)["config"], str(tokenizer_dir))  # before any data
    cache_dir = find_latent_cache(Path(data_dir), tokenizer_dir, cfg.data.latents)
    dataset = TokenDataset(cache_dir, cfg.data.frames or None, "train", cfg.data.holdout_percent)
    check_cache_tokenizer(dataset.cache, tokenizer_dir)
    cfg = resolve_for_data(cfg, dataset)
    torch.manual_seed(cfg.train.seed)  # the transformer's initial weights
    task = ARTask(cfg, dataset, tokenizer_dir)
    return train(task, cfg.train, out_dir, config_record=to_dict(cfg), stop_after=stop_after)


@torch.no_grad()
def write_sample_grid(
    cfg: ARModelConfig, state: dict[str, torch.Tensor], tokenizer_dir: Path, dataset, path: Path
) -> None:
    """A PNG of one sampled latent frame per caption of the first two dataset samples (training previews)."""
    from PIL import Image

    from drivewm.atomic import atomic_path
    from drivewm.tokenizer.model import Tokenizer

    with torch.random.fork_rng():
        model = ARTransformer(cfg.ar)
    model.load_state_dict(state)
    model.eval()
    samples = [dataset[i] for i in range(min(2, len(dataset)))]
    _, cond = batch_of(samples, build_text_encoder(cfg.text), cfg.ar)
    empty = torch.zeros(len(samples), 0, dtype=torch.long)
    tokens = sample_tokens(model, cond, empty, cfg.ar.frame_tokens, TokenSampling(), torch.Generator().manual_seed(0))
    tokenizer = Tokenizer.from_pretrained(tokenizer_dir)
    video = tokenizer.decode(tokenizer.quantizer.indices_to_codes(from_sequence(tokens, cfg.ar))).clamp(-1, 1)
    image = ((video[:, :, 0].permute(0, 2, 3, 1).flatten(0, 1) + 1) * 127.5).round().byte().numpy()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        Image.fromarray(image).save(tmp, format="PNG")
