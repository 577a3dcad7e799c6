"""Training throughput of drivewm's DiT vs diffusers' LTXVideoTransformer3DModel, same process.

Both models get the same width, depth, heads, text width and token count (LTX takes pre-patchified
tokens, so it is fed our 2x2 patches as channels); both run one full training step (forward, EDM or
MSE loss, backward, AdamW). Rounds alternate between the two so the shared machine's noise hits
both alike, and the fastest step of each counts (the least disturbed by other processes). Prints
latent tokens/s of each and the ratio (ours / peer); on CUDA also bf16 and MFU.

    python benchmarks/bench_dit.py            # small: D=192, depth 4, 288 tokens (seconds)
    python benchmarks/bench_dit.py --full     # D=384, depth 12, 2,240 tokens (minutes on a CPU)
"""

from __future__ import annotations

import argparse
import time

import torch

from drivewm.diffusion.denoiser import Conditioning, EDMConfig, EDMDenoiser, edm_loss
from drivewm.diffusion.dit import DiT, count_parameters, patchify
from drivewm.diffusion.dit_config import DiTConfig

SIZES = {
    "small": dict(hidden_dim=192, depth=4, num_heads=4, latent=(16, 3, 16, 24), batch=2),
    "full": dict(hidden_dim=384, depth=12, num_heads=6, latent=(16, 5, 32, 56), batch=1),
}
TEXT_DIM, TEXT_LEN = 256, 32


def ours(size: dict, device: torch.device):
    cfg = DiTConfig(
        in_channels=16,
        hidden_dim=size["hidden_dim"],
        depth=size["depth"],
        num_heads=size["num_heads"],
        text_dim=TEXT_DIM,
    )
    model = EDMDenoiser(DiT(cfg), EDMConfig()).to(device)
    b, (c, t, h, w) = size["batch"], size["latent"]
    x0, noise = torch.randn(b, c, t, h, w, device=device), torch.randn(b, c, t, h, w, device=device)
    cond = Conditioning(
        torch.randn(b, TEXT_LEN, TEXT_DIM, device=device),
        torch.ones(b, TEXT_LEN, dtype=torch.bool, device=device),
        torch.full((b,), 10.0, device=device),
    )
    sigma, keep = torch.full((b,), 1.0, device=device), torch.ones(b, dtype=torch.bool, device=device)
    return model, lambda: edm_loss(model, model.cfg, x0, cond, sigma, noise, keep)


def peer(size: dict, device: torch.device):
    from diffusers import LTXVideoTransformer3DModel

    d, heads = size["hidden_dim"], size["num_heads"]
    model = LTXVideoTransformer3DModel(
        in_channels=64,
        out_channels=64,
        num_attention_heads=heads,
        attention_head_dim=d // heads,
        cross_attention_dim=d,
        num_layers=size["depth"],
        caption_channels=TEXT_DIM,
    ).to(device)
    b, (c, t, h, w) = size["batch"], size["latent"]
    tokens = patchify(torch.randn(b, c, t, h, w), 2, 1).to(device)  # (B, N, 64): our patches as LTX voxels
    text = torch.randn(b, TEXT_LEN, TEXT_DIM, device=device)
    mask, step = torch.ones(b, TEXT_LEN, device=device), torch.full((b,), 500, device=device)
    target = torch.randn_like(tokens)

    def loss():
        out = model(tokens, text, step, mask, num_frames=t, height=h // 2, width=w // 2, return_dict=False)[0]
        return torch.nn.functional.mse_loss(out, target)

    return model, loss


def timed_step(model, loss_fn, opt, bf16: bool, device: torch.device) -> float:
    tic = time.perf_counter()
    with torch.autocast(device.type, dtype=torch.bfloat16, enabled=bf16):
        loss = loss_fn()
    loss.backward()
    opt.step()
    opt.zero_grad(set_to_none=True)
    if device.type == "cuda":
        torch.cuda.synchronize()
    return time.perf_counter() - tic


def train_flops(params: int, tokens: int, depth: int, dim: int) -> float:
    """6 N P for the dense layers plus 3 x (4 N^2 D) per block for self-attention scores/values."""
    return 6 * params * tokens + 3 * 4 * depth * tokens**2 * dim


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="bigger model and sequence")
    parser.add_argument("--rounds", type=int, default=8, help="timed steps per model")
    parser.add_argument("--threads", type=int, default=1, help="CPU intra-op threads")
    parser.add_argument(
        "--peak-tflops", type=float, default=989.0, help="GPU peak bf16 TFLOP/s for MFU (H100 SXM: 989)"
    )
    args = parser.parse_args()
    size = SIZES["full" if args.full else "small"]
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    torch.set_num_threads(args.threads)
    bf16 = device.type == "cuda"
    torch.manual_seed(0)
    runs = {name: build(size, device) for name, build in (("drivewm DiT", ours), ("diffusers LTX", peer))}
    opts = {name: torch.optim.AdamW(m.parameters(), lr=1e-4) for name, (m, _) in runs.items()}
    times = {name: [] for name in runs}
    for r in range(args.rounds + 1):  # round 0 warms up
        for name, (model, loss_fn) in runs.items():
            dt = timed_step(model, loss_fn, opts[name], bf16, device)
            if r:
                times[name].append(dt)
    c, t, h, w = size["latent"]
    tokens = size["batch"] * t * (h // 2) * (w // 2)
    print(
        f"device {device}, {'bf16 autocast' if bf16 else 'fp32'}, batch {size['batch']} x {tokens // size['batch']} "
        "tokens, "
        f"D={size['hidden_dim']} depth {size['depth']}"
    )
    rate = {}
    for name, (model, _) in runs.items():
        step_s = min(times[name])
        rate[name] = tokens / step_s
        params_m = count_parameters(model) / 1e6
        line = f"{name:14s} {params_m:6.1f}M params  {step_s * 1e3:8.1f} ms/step  {rate[name]:9.0f} tokens/s"
        if device.type == "cuda":
            mfu = (
                train_flops(count_parameters(model), tokens, size["depth"], size["hidden_dim"])
                / step_s
                / (args.peak_tflops * 1e12)
            )
            line += f"  MFU {mfu:.1%}"
        print(line)
    print(f"ratio drivewm/LTX tokens/s: {rate['drivewm DiT'] / rate['diffusers LTX']:.2f}")


if __name__ == "__main__":
    main()
