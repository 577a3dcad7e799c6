"""The tokenizer network: shapes, Haar invertibility, causality, chunking/tiling, save/load, bad input."""

import json

import pytest
import torch
from einops import rearrange

from drivewm.errors import DrivewmError
from drivewm.tokenizer import Tokenizer, preset
from drivewm.tokenizer.causal import CausalContext
from drivewm.tokenizer.fsq import FSQ
from drivewm.tokenizer.tiling import TilingConfig, decode_tiled, encode_tiled
from drivewm.tokenizer.wavelet import SQRT2, haar_space, haar_time


def inverse_haar_space(y: torch.Tensor) -> torch.Tensor:
    """(B, 4C, T, h, w) -> (B, C, T, 2h, 2w); the inverse of drivewm.tokenizer.wavelet.haar_space."""
    ll, lh, hl, hh = y.chunk(4, dim=1)
    a, b = (ll + lh + hl + hh) / 2, (ll - lh + hl - hh) / 2
    c, d = (ll + lh - hl - hh) / 2, (ll - lh - hl + hh) / 2
    top = rearrange([a, b], "two b c t h w -> b c t h (w two)")
    bottom = rearrange([c, d], "two b c t h w -> b c t h (w two)")
    return rearrange([top, bottom], "two b c t h w -> b c t (h two) w")


def inverse_haar_time(y: torch.Tensor, first_chunk: bool = True) -> torch.Tensor:
    """(B, 2C, T', H, W) -> (B, C, T, H, W); the inverse of haar_time: drops the
    duplicated frame 0 of a first chunk."""
    low, high = y.chunk(2, dim=1)
    x = rearrange([(low + high) / SQRT2, (low - high) / SQRT2], "two b c t h w -> b c (t two) h w")
    return x[:, :, 1:] if first_chunk else x


def random_video(T, H=64, W=96, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(1, 3, T, H, W, generator=g) * 2 - 1


@pytest.fixture(scope="module", params=[("4x8x8", False), ("8x8x8", False), ("8x8x8", True)])
def tok(request):
    torch.manual_seed(0)
    return Tokenizer(preset("debug", *request.param)).eval()


def test_haar_is_orthonormal_and_invertible():
    x = random_video(9)
    y = haar_time(haar_space(x))
    assert y.shape == (1, 24, 5, 32, 48)
    assert torch.allclose(inverse_haar_space(inverse_haar_time(y)), x, atol=1e-6)
    # orthonormal: energy is kept (frame 0 counts twice, paired with its copy)
    energy = x.pow(2).sum() + x[:, :, :1].pow(2).sum()
    assert torch.allclose(y.pow(2).sum(), energy, rtol=1e-5)


def test_presets_have_the_advertised_shapes():
    for name in [("4x8x8", False), ("8x8x8", False), ("8x8x8", True), ("1x8x8", False), ("8x16x16", False)]:
        cfg = preset("debug", *name)
        torch.manual_seed(0)
        model = Tokenizer(cfg).eval()
        f, s = cfg.temporal_compression, cfg.spatial_compression
        video = random_video(1 + 2 * f)
        with torch.no_grad():
            z = model.encode(video)
            assert z.shape == (1, cfg.code_channels, 3, 64 // s, 96 // s), name
            assert model.decode(z).shape == video.shape
            image = model.encode(video[:, :, :1])  # T = 1: image use
            assert image.shape[2] == 1 and torch.allclose(image, z[:, :, :1], atol=1e-5)
    assert preset("debug").code_channels == 16 and preset("debug", fsq=True).code_channels == 4


@torch.no_grad()
def test_causality_leading_latents_equal(tok):
    f = tok.config.temporal_compression
    video = random_video(1 + 3 * f)
    whole = tok.encode(video)
    for k in range(3):
        head = tok.encode(video[:, :, : 1 + k * f])
        assert torch.allclose(head, whole[:, :, : 1 + k], atol=1e-5)
    # and the decoder: the first frames depend only on the first latents
    frames = tok.decode(whole)
    assert torch.allclose(tok.decode(whole[:, :, :2]), frames[:, :, : 1 + f], atol=1e-5)
    # a change in the last frame must not move earlier latents, and must move the last one
    changed = video.clone()
    changed[:, :, -1] = -changed[:, :, -1]
    z2 = tok.encode(changed)
    assert torch.allclose(z2[:, :, :-1], whole[:, :, :-1], atol=1e-6)
    assert not torch.allclose(z2[:, :, -1], whole[:, :, -1])


@torch.no_grad()
def test_chunked_equals_one_pass(tok):
    f = tok.config.temporal_compression
    video = random_video(1 + 3 * f, 32, 64, seed=1)
    z = tok.encode(video)
    recon = tok.decode(z)
    for n in (1, 2):
        chunked = TilingConfig(chunk_latent_frames=n, tile_latent=None)
        assert torch.allclose(encode_tiled(tok, video, chunked), z, atol=1e-5)
        assert torch.allclose(decode_tiled(tok, z, chunked), recon, atol=1e-5)
    # a context carries the state by hand, too
    ctx = CausalContext()
    first = tok.encode(video[:, :, : 1 + f], ctx)
    ctx.next_chunk()
    rest = tok.encode(video[:, :, 1 + f :], ctx)
    assert torch.allclose(torch.cat([first, rest], 2), z, atol=1e-5)


def test_fsq_round_trip_and_levels():
    fsq = FSQ([8, 5, 5, 5])
    z = torch.randn(2, 4, 3, 5, 7) * 3
    codes = fsq(z)
    idx = fsq.codes_to_indices(codes)
    assert idx.min() >= 0 and idx.max() < 1000 and fsq.codebook_size == 1000
    assert torch.equal(fsq.indices_to_codes(idx), codes)
    for ch, levels in enumerate([8, 5, 5, 5]):
        assert len(codes[:, ch].unique()) <= levels
    big = fsq(torch.linspace(-20, 20, 2001).view(1, 1, -1, 1, 1).expand(1, 4, -1, 1, 1).contiguous())
    assert [len(big[:, c].unique()) for c in range(4)] == [8, 5, 5, 5]  # every level reachable


def test_save_load_encode_identical_and_no_pickle(tmp_path, tok):
    tok.latent_mean.fill_(0.25)
    tok.save_pretrained(tmp_path / "tok")
    assert sorted(p.name for p in (tmp_path / "tok").iterdir()) == ["config.json", "model.safetensors"]
    loaded = Tokenizer.from_pretrained(tmp_path / "tok")
    video = random_video(1 + tok.config.temporal_compression)
    with torch.no_grad():
        assert torch.equal(loaded.encode(video), tok.encode(video))
    assert torch.equal(loaded.latent_mean, tok.latent_mean)
    info = json.loads((tmp_path / "tok" / "config.json").read_text())
    assert info["latent_mean"][0] == 0.25 and info["config"]["quantizer"] == tok.config.quantizer


def test_bad_input_is_a_clear_error(tmp_path):
    torch.manual_seed(0)
    model = Tokenizer(preset("debug")).eval()
    with pytest.raises(DrivewmError, match="4 channels"):
        model.encode(torch.zeros(1, 4, 5, 64, 64))
    with pytest.raises(DrivewmError, match=r"6 frames.*1 \+ k\*4"):
        model.encode(torch.zeros(1, 3, 6, 64, 64))
    with pytest.raises(DrivewmError, match=r"multiples of 8 \(e.g. 64x56 WxH.*resolution=\[64,56\]"):
        model.encode(torch.zeros(1, 3, 5, 60, 64))  # the message names a size that works
    with pytest.raises(DrivewmError, match=r"\(B, 3, T, H, W\)"):
        model.encode(torch.zeros(3, 5, 64, 64))
    with pytest.raises(DrivewmError, match="latents must be"):
        model.decode(torch.zeros(1, 4, 2, 8, 8))
    # a model folder whose weights belong to another config
    model.save_pretrained(tmp_path / "a")
    other = Tokenizer(preset("debug", "8x8x8", fsq=True))
    other.save_pretrained(tmp_path / "b")
    (tmp_path / "b" / "config.json").write_text((tmp_path / "a" / "config.json").read_text())
    with pytest.raises(DrivewmError, match="config.json .* and model.safetensors .* come from different saves"):
        Tokenizer.from_pretrained(tmp_path / "b")
    hand_made = {k: v for k, v in json.loads((tmp_path / "a" / "config.json").read_text()).items() if k != "revision"}
    (tmp_path / "b" / "config.json").write_text(json.dumps(hand_made))
    with pytest.raises(DrivewmError, match="does not match config.json"):
        Tokenizer.from_pretrained(tmp_path / "b")
    with pytest.raises(DrivewmError, match="not a drivewm model folder"):
        Tokenizer.from_pretrained(tmp_path / "missing")
    with pytest.raises(DrivewmError, match="unknown tokenizer size 'huge-3x3x3'"):
        preset("huge-3x3x3")
