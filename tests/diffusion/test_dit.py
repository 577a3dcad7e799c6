"""DiT backbone: shapes, 3D RoPE with fps scaling, conditioning hooks and extension by config."""

from __future__ import annotations

import dataclasses

import pytest
import torch
from synthetic_latents import make_synthetic_latent_cache
from torch import nn

from drivewm.cli import main
from drivewm.diffusion.blocks import SUBLAYERS, BlockContext, DiTBlock, register_sublayer
from drivewm.diffusion.dit import DiT, count_parameters, patchify, unpatchify
from drivewm.diffusion.dit_config import DIT_PRESETS, DiTConfig, dit_preset
from drivewm.diffusion.rope import grid_positions, rope_angles, rope_rotation, rotate
from drivewm.errors import DrivewmError

CFG = DiTConfig(in_channels=4, hidden_dim=64, depth=2, num_heads=4, text_dim=16, adaln_lora_dim=8)


def _randomize(model: nn.Module) -> nn.Module:
    """Zero-initialised outputs make a fresh DiT return 0; give every weight a value to test wiring."""
    torch.manual_seed(1)
    with torch.no_grad():
        for p in model.parameters():
            p.copy_(torch.randn_like(p) * 0.2)
    return model


def _inputs(b: int = 2, t: int = 3, fps: float = 10.0):
    g = torch.Generator().manual_seed(0)
    x = torch.randn(b, 4, t, 4, 6, generator=g)
    return (
        x,
        torch.zeros(b),
        torch.randn(b, 5, 16, generator=g),
        torch.ones(b, 5, dtype=torch.bool),
        torch.full((b,), fps),
    )


def test_patchify_roundtrip_and_output_shape():
    x = torch.randn(2, 4, 4, 6, 8)
    assert torch.equal(unpatchify(patchify(x, 2, 2), (2, 3, 4), 2, 2), x)
    model = _randomize(DiT(CFG))
    assert model(*_inputs()).shape == (2, 4, 3, 4, 6)


def test_fresh_dit_outputs_zero_so_edm_starts_at_c_skip_x():
    assert DiT(CFG)(*_inputs()).abs().max() == 0


def apply_rope(x: torch.Tensor, angles: torch.Tensor) -> torch.Tensor:
    """Rotate ``x`` (B, heads, N, head_dim) by ``angles`` (B, N, head_dim // 2) as attention does
    (drivewm.diffusion.rope.rotate), pairing adjacent channels."""
    return rotate(x, rope_rotation(angles).unsqueeze(1))


def _rope_by_pairs(x: torch.Tensor, angles: torch.Tensor) -> torch.Tensor:
    """RoFormer eq. 34 written out: (x_2j, x_2j+1) -> (x_2j cos - x_2j+1 sin, x_2j sin + x_2j+1 cos)."""
    cos, sin = angles.cos().unsqueeze(1), angles.sin().unsqueeze(1)
    even, odd = x[..., 0::2], x[..., 1::2]
    return torch.stack([even * cos - odd * sin, even * sin + odd * cos], dim=-1).flatten(-2)


def test_complex_rope_equals_the_pairwise_rotation():
    pos = grid_positions(3, 2, 4, torch.tensor([10.0, 5.0]), base_fps=10.0)
    ang = rope_angles(pos, 24)  # (2, 24, 12)
    x = torch.randn(2, 3, 24, 24, generator=torch.Generator().manual_seed(0))  # (B, heads, N, hd)
    assert torch.allclose(apply_rope(x, ang), _rope_by_pairs(x, ang), atol=1e-5)


def test_rope_rotations_are_computed_once_per_grid_and_frame_rate():
    model = DiT(CFG)
    ten, five = torch.full((2,), 10.0), torch.full((2,), 5.0)
    first = model.rope((3, 2, 3), ten)
    assert model.rope((3, 2, 3), ten) is first and first.shape == (1, 18, 1, CFG.head_dim // 2)
    assert not torch.allclose(model.rope((3, 2, 3), five), first)
    # A batch of clips at different rates gets each clip's own rotations.
    mixed = model.rope((3, 2, 3), torch.tensor([10.0, 5.0]))
    assert torch.equal(mixed[:1], first) and torch.equal(mixed[1:], model.rope((3, 2, 3), five))
    # Made under inference mode, the cached rotations still serve a training step afterwards.
    fresh = _randomize(DiT(CFG))
    with torch.inference_mode():
        fresh(*_inputs())
    fresh(*_inputs()).square().mean().backward()
    assert fresh.patch_embed.weight.grad is not None


def test_rope_is_relative_and_fps_scaled():
    # Rotating q and k by their positions makes q.k depend on the offset only.
    pos = grid_positions(4, 2, 2, torch.tensor([10.0]), base_fps=10.0)
    ang = rope_angles(pos, 24)
    q, k = torch.randn(1, 1, 1, 24).expand(1, 1, 16, 24), torch.randn(1, 1, 1, 24).expand(1, 1, 16, 24)
    dots = (apply_rope(q, ang) * apply_rope(k, ang)).sum(-1)  # same offset (0) for every token
    assert torch.allclose(dots, dots[..., :1].expand_as(dots), atol=1e-5)
    # A clip at 5 fps: latent frame i sits where frame 2i of a 10 fps clip sits (same time).
    slow = grid_positions(4, 2, 2, torch.tensor([5.0]), base_fps=10.0)
    assert torch.equal(slow[0, 4 * 1 : 4 * 2, 0], pos[0, 4 * 2 : 4 * 3, 0])
    assert torch.equal(slow[..., 1:], pos[..., 1:])


def _every_other(rotations: torch.Tensor) -> torch.Tensor:
    """Rows and columns 0, 2, 4, ... of a (1, 2*4*6, 1, k) rotation grid: (1, 12, 1, k)."""
    return rotations.reshape(2, 4, 6, -1)[:, ::2, ::2].reshape(1, 12, 1, -1)


def test_a_spatial_scale_puts_a_larger_grid_on_the_positions_of_the_smaller():
    """rope_spatial_scale 0.5 (position interpolation): token (2i, 2j) of a 4x6 grid turns by what
    token (i, j) of the 2x3 grid turns by, so a model trained on the 2x3 grid meets no new position."""
    small = DiT(CFG).rope((2, 2, 3), torch.full((1,), 10.0))  # (1, 12, 1, hd/2)
    large = DiT(dataclasses.replace(CFG, rope_spatial_scale=0.5)).rope((2, 4, 6), torch.full((1,), 10.0))
    assert torch.allclose(_every_other(large), small, atol=1e-6)
    unscaled = DiT(CFG).rope((2, 4, 6), torch.full((1,), 10.0))  # extrapolates: positions up to (3, 5)
    assert not torch.allclose(_every_other(unscaled), small, atol=1e-3)
    with pytest.raises(DrivewmError, match="rope_spatial_scale"):
        dataclasses.replace(CFG, rope_spatial_scale=0.0).validate()


#: The two ways text enters a block: joint attention (default) and the older self- + cross-attention.
LAYOUTS = [["joint_attn", "mlp"], ["self_attn", "cross_attn", "mlp"]]


@pytest.mark.parametrize("layers", LAYOUTS, ids=["joint", "self+cross"])
def test_output_depends_on_text_fps_and_extra_conditions_but_not_masked_tokens(layers):
    model = _randomize(DiT(dataclasses.replace(CFG, block_layers=layers))).eval()
    x, noise, text, mask, fps = _inputs()
    base = model(x, noise, text, mask, fps)
    masked = mask.clone()
    masked[:, 3:] = False
    altered = text.clone()
    altered[:, 3:] += 5.0
    assert torch.allclose(model(x, noise, text, masked, fps), model(x, noise, altered, masked, fps), atol=1e-5)
    assert not torch.allclose(model(x, noise, altered, mask, fps), base, atol=1e-3)
    assert not torch.allclose(model(x, noise, text, mask, fps * 2), base, atol=1e-3)
    n_tok = 3 * 2 * 3
    assert not torch.allclose(
        model(x, noise, text, mask, fps, extra_token_cond=torch.randn(2, n_tok, 64)), base, atol=1e-3
    )
    assert not torch.allclose(model(x, noise, text, mask, fps, extra_global_cond=torch.randn(2, 64)), base, atol=1e-3)
    # A caption dropped entirely (CFG) still gives finite output through the null token.
    assert torch.isfinite(model(x, noise, text, torch.zeros_like(mask), fps)).all()


class _ScaledCopy(nn.Module):
    """A toy extra sub-layer (stands in for cross-view attention): zero-initialised output."""

    def __init__(self, cfg: DiTConfig):
        super().__init__()
        self.out = nn.Linear(cfg.hidden_dim, cfg.hidden_dim)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def forward(self, x, ctx):
        return self.out(x) * ctx.num_views


def test_inserting_a_sublayer_by_config_starts_as_the_original_model():
    register_sublayer("toy_view_attn", _ScaledCopy)
    try:
        base = _randomize(DiT(CFG)).eval()
        extended = DiT(
            dataclasses.replace(CFG, block_layers=[CFG.block_layers[0], "toy_view_attn", *CFG.block_layers[1:]])
        ).eval()
        missing, unexpected = extended.load_state_dict(base.state_dict(), strict=False)
        assert not unexpected and all(".toy_view_attn." in k for k in missing)
        assert torch.allclose(extended(*_inputs(), num_views=3), base(*_inputs()), atol=1e-6)
    finally:
        SUBLAYERS.pop("toy_view_attn")


def test_unknown_sublayer_is_a_one_line_error(tmp_path, capsys):
    with pytest.raises(DrivewmError, match="unknown block layer 'nope'.*registered: .*'self_attn'"):
        DiT(dataclasses.replace(CFG, block_layers=["self_attn", "nope", "mlp"]))
    cache = make_synthetic_latent_cache(tmp_path / "latents", clips_per_condition=1)
    argv = ["pretrain", "--data", str(cache), "--out", str(tmp_path / "t2w"), "--set", "model.block_layers=[nope]"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "'nope'" in err


def test_presets_span_debug_to_about_1b():
    counts = {}
    for name in DIT_PRESETS:
        with torch.device("meta"):
            counts[name] = count_parameters(DiT(DiTConfig(**dit_preset(name))))
    assert 1e6 < counts["debug"] < 5e6 and 0.9e9 < counts["xl"] < 1.5e9
    assert list(counts.values()) == sorted(counts.values())
    with pytest.raises(DrivewmError, match="unknown preset 'huge'"):
        dit_preset("huge")
    with pytest.raises(DrivewmError, match="heads"):
        DiT(DiTConfig(hidden_dim=65, num_heads=4))


def test_a_folder_saved_before_a_config_field_loads_as_it_was_trained(tmp_path):
    """config.json written before ``mlp_activation`` existed: the tanh GELU those models were trained with."""
    import json

    from drivewm.diffusion.text2world import LatentInfo, Text2World, Text2WorldConfig

    old = Text2World(
        Text2WorldConfig(dataclasses.replace(CFG, text_dim=256, mlp_activation="gelu_tanh")),
        LatentInfo([4, 3, 4, 6], [0.0] * 4, [1.0] * 4),
    )
    old.save_pretrained(tmp_path)
    info = json.loads((tmp_path / "config.json").read_text())
    del info["config"]["dit"]["mlp_activation"]
    (tmp_path / "config.json").write_text(json.dumps(info))
    assert Text2World.from_pretrained(tmp_path).cfg.dit.mlp_activation == "gelu_tanh"
    assert DiTConfig().mlp_activation == "gelu"  # new models: exact GELU (faster on the CPU)


def test_full_attn_every_picks_the_full_blocks_counting_back_from_the_last():
    pick = [DiTConfig(depth=12, full_attn_every=k).frame_local(i) for k in (1, 3) for i in range(12)]
    assert pick[:12] == [False] * 12
    assert [i for i in range(12) if not pick[12 + i]] == [2, 5, 8, 11]
    assert [i for i in range(6) if not DiTConfig(depth=6, full_attn_every=4).frame_local(i)] == [1, 5]
    with pytest.raises(DrivewmError, match="full_attn_every"):
        DiT(DiTConfig(full_attn_every=0))


@pytest.mark.parametrize("layers", LAYOUTS, ids=["joint", "self+cross"])
def test_a_frame_local_block_keeps_latent_frames_apart_and_a_full_block_does_not(layers):
    """Tokens of frame 2 changed: a frame-local block's output for frames 0 and 1 is bit-identical
    (the caption still reaches every frame), a full block's is not."""
    cfg = dataclasses.replace(CFG, block_layers=layers)
    x, noise, text, mask, fps = _inputs()
    model = _randomize(DiT(cfg))
    ctx = BlockContext(model.rope((3, 2, 3), fps), *model.embed_text(text, mask), (3, 2, 3))
    emb, lora = model.time_embed(noise, None)
    tokens = torch.randn(2, 18, 64)
    changed = tokens.clone()
    changed[:, 12:] += 1.0  # frame 2 of (t, h, w) = (3, 2, 3)
    for frame_local in (True, False):
        block = _randomize(DiTBlock(cfg, frame_local)).eval()
        a, b = block(tokens, emb, lora, ctx), block(changed, emb, lora, ctx)
        assert torch.equal(a[:, :12], b[:, :12]) == frame_local
        assert not torch.allclose(a[:, 12:], b[:, 12:])
    local = _randomize(DiTBlock(cfg, True)).eval()
    other_text = BlockContext(ctx.rope, ctx.text + 1.0, ctx.text_mask, ctx.grid_thw)
    assert not torch.allclose(local(tokens, emb, lora, ctx)[:, :6], local(tokens, emb, lora, other_text)[:, :6])


def test_attention_layouts_share_parameters_and_agree_on_images():
    """Weights of a full-attention DiT load into a frame-local layout unchanged; on one latent frame
    (images) the two are the same function, on video they differ."""
    full = _randomize(DiT(dataclasses.replace(CFG, depth=3))).eval()
    hybrid = DiT(dataclasses.replace(CFG, depth=3, full_attn_every=2)).eval()
    hybrid.load_state_dict(full.state_dict())
    assert torch.equal(full(*_inputs(t=1)), hybrid(*_inputs(t=1)))
    assert not torch.allclose(full(*_inputs(t=3)), hybrid(*_inputs(t=3)), atol=1e-4)
