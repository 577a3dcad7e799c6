"""The DiT's typed config and its named size presets (``debug`` on a CPU up to ``xl``, about 1B)."""

from __future__ import annotations

import dataclasses
from typing import Literal

from drivewm.config import above, at_least
from drivewm.errors import DrivewmError

#: DiTConfig fields added after model folders were first written, with the value those folders were
#: trained with (a folder's config.json without the field gets it, so old folders load unchanged).
SAVED_BEFORE = {"mlp_activation": "gelu_tanh"}


@dataclasses.dataclass
class DiTConfig:
    """Shape of the diffusion transformer. Tokens are (latent frame, row, column) patches."""

    in_channels: int = 16
    """Latent channels c of the tokenizer (the DiT predicts the same number)."""
    patch_size: int = 2
    """Spatial patch side in latent pixels: a latent frame of h x w gives (h/p)*(w/p) tokens."""
    patch_t: int = 1
    """Temporal patch length in latent frames."""
    hidden_dim: int = 128
    """Token width D."""
    depth: int = 4
    """Number of blocks."""
    num_heads: int = 4
    """Attention heads (head_dim = hidden_dim / num_heads, even, split over t/h/w by 3D RoPE)."""
    mlp_ratio: float = 4.0
    """MLP hidden width as a multiple of D."""
    mlp_activation: Literal["gelu", "gelu_tanh"] = "gelu"
    """MLP nonlinearity: exact GELU (erf), or its tanh approximation (folders written before this field;
    2.7x slower than erf on the CPU, where PyTorch vectorises erf but not the tanh form)."""
    text_dim: int = 256
    """Width of the text encoder's token embeddings (projected to D inside the DiT)."""
    adaln_lora_dim: int = 64
    """Rank of the per-block AdaLN-LoRA modulation (Cosmos sec. 5.1 uses 256)."""
    block_layers: list[str] = dataclasses.field(default_factory=lambda: ["joint_attn", "mlp"])
    """Sub-layers of every block, in order, by registered name (drivewm.diffusion.blocks.SUBLAYERS):
    ``joint_attn`` (self-attention that also reads the caption) or ``self_attn`` + ``cross_attn``
    (folders written before joint attention), then ``mlp``; the multi-view model inserts e.g. a
    cross-view attention here."""
    rope_theta: float = 10000.0
    """RoPE base wavelength."""
    rope_base_fps: float = 10.0
    """Video frame rate at which the temporal RoPE position of latent frame i is exactly i."""
    rope_spatial_scale: float = 1.0
    """Row and column RoPE positions are ``index * rope_spatial_scale``. A model fine-tuned at twice
    its training size in each direction may take 0.5, so its larger token grid spans the positions it
    was trained on, at finer steps (position interpolation, Chen et al. 2023, arXiv 2306.15595), instead
    of positions it never saw."""
    cond_mask_channel: bool = False
    """Video2World: one extra input channel marks clean conditioning latent frames."""
    full_attn_every: int = 1
    """Attention layout over time: every k-th block (counted back from the last, which is always one)
    attends across the whole clip; the blocks between attend within their own latent frame, to that
    frame's tokens and the caption (factorised space-time attention as GAIA-2's, arXiv 2503.20523,
    with full blocks instead of temporal-only ones). A frame-local block at t latent frames spends 1/t
    of a full block's attention FLOPs with the same parameters, so a model trained either way loads
    the other way. 1 = every block full (Cosmos, CogVideoX; the layout of folders written before this
    field). One latent frame (images): every layout is the same network."""
    control_depth: int = 0
    """Blocks of a ControlNet branch (Zhang et al. 2023, applied to a DiT as in PixArt-delta, Chen et al.
    2024): a trainable copy of the first ``control_depth`` blocks reads the patch tokens plus a control
    input (``control_tokens``) and adds each block's output, through a zero-initialised projection, to
    the matching main block's. 0 = no branch."""

    @property
    def head_dim(self) -> int:
        return self.hidden_dim // self.num_heads

    def frame_local(self, block: int) -> bool:
        """Whether block ``block`` (0-based) attends within latent frames (see :attr:`full_attn_every`)."""
        return (self.depth - 1 - block) % self.full_attn_every != 0

    def validate(self) -> None:
        at_least(self, 1, "in_channels", "patch_size", "patch_t", "hidden_dim", "depth", "num_heads", "text_dim")
        at_least(self, 1, "adaln_lora_dim", "full_attn_every")
        at_least(self, 0, "control_depth")
        if self.control_depth > self.depth:
            raise DrivewmError(f"dit: control_depth {self.control_depth} exceeds the {self.depth} blocks it copies")
        above(self, 0, "mlp_ratio", "rope_theta", "rope_base_fps", "rope_spatial_scale")
        if self.hidden_dim % self.num_heads or self.head_dim % 2:
            raise DrivewmError(
                f"dit: hidden_dim {self.hidden_dim} must split into {self.num_heads} heads of even width"
            )
        if not self.block_layers or len(set(self.block_layers)) != len(self.block_layers):
            raise DrivewmError(f"dit: block_layers must be non-empty and unique, got {self.block_layers}")


#: Named sizes (DiT-paper style). Parameter counts at text_dim=256, in_channels=16, p=2:
#: debug ~1.3M, tiny ~5.5M (the shipped CPU size), small ~28M, base ~113M, large ~411M, xl ~1.0B
#: (joint attention; the older self + cross attention layout: ~1.5M, 33M, 132M, 486M, 1.2B).
#: ``small`` and up attend across the clip in every third block and within latent frames between
#: (``full_attn_every``): on 2,160-token clips that layout reached a lower held-out x0 error than full
#: attention at equal CPU time, training 1.8x the steps (studies/attention_layout.py, docs/DESIGN.md).
#: ``debug`` and ``tiny`` keep full attention: at their 300-token CPU clips attention is a small part
#: of a step, and the shipped models were trained so.
DIT_PRESETS: dict[str, dict] = {
    "debug": dict(hidden_dim=128, depth=4, num_heads=4, adaln_lora_dim=32),
    "tiny": dict(hidden_dim=224, depth=6, num_heads=4, adaln_lora_dim=64),  # the shipped CPU size
    "small": dict(hidden_dim=384, depth=12, num_heads=6, adaln_lora_dim=64, full_attn_every=3),
    "base": dict(hidden_dim=768, depth=12, num_heads=12, adaln_lora_dim=128, full_attn_every=3),
    "large": dict(hidden_dim=1024, depth=24, num_heads=16, adaln_lora_dim=256, full_attn_every=3),
    "xl": dict(hidden_dim=1536, depth=28, num_heads=24, adaln_lora_dim=256, full_attn_every=3),
}


#: EDMConfig fields whose default changed after model folders were first written, with the value those folders
#: were trained with: the default became rectified flow on measured evidence (docs/quality-vs-compute.md), and a
#: folder whose config.json names no parameterization was trained as EDM.
EDM_SAVED_BEFORE = {"parameterization": "edm"}


def upgrade_saved_config(config: dict) -> dict:
    """A saved model config (its ``dit`` and ``edm`` sections) with the fields they predate filled in as the
    folder was trained (:data:`SAVED_BEFORE`, :data:`EDM_SAVED_BEFORE`), so old folders load unchanged."""
    dit, edm = config.get("dit", {}), config.get("edm", {})
    return {  # a section that is no mapping stays as it is, for from_dict to name it
        **config,
        "dit": {**SAVED_BEFORE, **dit} if isinstance(dit, dict) else dit,
        "edm": {**EDM_SAVED_BEFORE, **edm} if isinstance(edm, dict) else edm,
    }


def dit_preset(name: str) -> dict:
    """The preset's fields as a dict (copy); an unknown name raises DrivewmError listing the known ones."""
    if name not in DIT_PRESETS:
        raise DrivewmError(f"unknown preset {name!r}; known: {sorted(DIT_PRESETS)}")
    return dict(DIT_PRESETS[name])
