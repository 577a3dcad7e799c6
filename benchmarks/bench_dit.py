"""Training throughput of drivewm's DiT against diffusers' CogVideoX, LTX-Video and Wan transformers.

Every model is built from a config (never from the hub) at the same token width, depth, heads, text
width and sequence length, with its parameter count within ~10% of ours (CogVideoX's per-block
timestep projections are large, so its ``time_embed_dim`` is the one chosen to match). Each runs one
full training step per round: forward, loss (EDM for ours, MSE for the peers), backward, AdamW.
Rounds alternate between the models so the shared machine's noise hits all alike; the median step
time counts (the process's CPU time on a CPU, wall time on CUDA). Every model uses the same optimizer
(fused AdamW). Prints parameter counts, latent tokens/s, the ratio of ours to each peer and to the
best peer, and model-FLOPs utilisation against the device's peak measured in the same run by a large
matmul (bf16 autocast on CUDA, fp32 on the CPU).

FLOPs of a training step are counted as 6 x params x tokens (forward + backward of every weight)
plus 12 x layers x tokens^2 x width (QK^T and PV, forward and backward) -- the PaLM appendix B count;
a frame-local block of ours (``full_attn_every`` > 1: attention within each of t latent frames)
counts 1/t of a layer. Ours runs twice: every block full (the layout of the shipped models and of
the debug and tiny presets) and full every FRAME_LOCAL_EVERY blocks, frame-local between (the layout
of the small to xl presets, the same parameters; its quality against full attention at equal
compute: studies/attention_layout.py).

    python benchmarks/bench_dit.py                 # small: D=192, depth 4, 2 x 288 tokens (a minute)
    python benchmarks/bench_dit.py --size full     # D=384, depth 12, 2,240 tokens (the issue-19 target)
    python benchmarks/bench_dit.py --profile       # also each model's step time per op class (torch.profiler)
    python benchmarks/bench_dit.py --mfu-size base # also our DiT alone at the base preset, fp32 on a CPU (on CUDA:
                                                   # by default, bf16, batch 16 x 2,240 tokens)
"""

from __future__ import annotations

import argparse
import functools
import os
import statistics
import time
from collections.abc import Callable

import torch
import torch.nn.functional as F

from drivewm.diffusion.denoiser import Conditioning, EDMConfig, EDMDenoiser, edm_loss
from drivewm.diffusion.dit import DiT, count_parameters, patchify
from drivewm.diffusion.dit_config import DiTConfig, dit_preset

#: Model shape and one sample's latents (c, t, h, w); patch 2 gives t * h/2 * w/2 tokens per sample.
SIZES = {
    "small": dict(hidden_dim=192, depth=4, num_heads=4, latent=(16, 3, 16, 24), batch=2),
    "full": dict(hidden_dim=384, depth=12, num_heads=6, latent=(16, 5, 32, 56), batch=1),
    "base": dict(
        **{k: dit_preset("base")[k] for k in ("hidden_dim", "depth", "num_heads")}, latent=(16, 5, 32, 56), batch=1
    ),
}
TEXT_DIM, TEXT_LEN = 256, 32

Build = Callable[[dict, torch.device], tuple[torch.nn.Module, Callable[[], torch.Tensor]]]


def ours(size: dict, device: torch.device, full_attn_every: int = 1):
    """drivewm's DiT; ``full_attn_every`` > 1: the blocks between every k-th attend within latent frames."""
    cfg = DiTConfig(
        in_channels=16,
        hidden_dim=size["hidden_dim"],
        depth=size["depth"],
        num_heads=size["num_heads"],
        text_dim=TEXT_DIM,
        full_attn_every=full_attn_every,
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


def cogvideox_model(size: dict, time_embed_dim: int):
    from diffusers import CogVideoXTransformer3DModel

    d, heads, (c, t, h, w) = size["hidden_dim"], size["num_heads"], size["latent"]
    return CogVideoXTransformer3DModel(
        num_attention_heads=heads,
        attention_head_dim=d // heads,
        in_channels=c,
        out_channels=c,
        time_embed_dim=time_embed_dim,
        text_embed_dim=TEXT_DIM,
        num_layers=size["depth"],
        sample_width=w,
        sample_height=h,
        sample_frames=1 + 4 * (t - 1),
        max_text_seq_length=TEXT_LEN,
        use_rotary_positional_embeddings=True,
    )


def cogvideox(size: dict, device: torch.device):
    """CogVideoX (joint text-video attention, 3D RoPE) with the time_embed_dim closest to our count."""
    from diffusers.models.embeddings import get_3d_rotary_pos_embed

    with torch.device("meta"):
        target = count_parameters(ours(size, torch.device("meta"))[0])
        ted = min((128, 256, 384, 512), key=lambda k: abs(count_parameters(cogvideox_model(size, k)) - target))
    model = cogvideox_model(size, ted).to(device)
    b, (c, t, h, w) = size["batch"], size["latent"]
    latents = torch.randn(b, t, c, h, w, device=device)  # CogVideoX takes (B, T, C, H, W)
    text, step = torch.randn(b, TEXT_LEN, TEXT_DIM, device=device), torch.full((b,), 500, device=device)
    target, d_head = torch.randn_like(latents), size["hidden_dim"] // size["num_heads"]

    def loss():  # RoPE per step, as CogVideoX's training script computes it
        rope = get_3d_rotary_pos_embed(d_head, ((0, 0), (h // 2, w // 2)), (h // 2, w // 2), t, device=device)
        out = model(latents, text, step, image_rotary_emb=rope, return_dict=False)[0]
        return F.mse_loss(out, target)

    return model, loss


def ltx(size: dict, device: torch.device):
    """LTX-Video (cross-attention to text, 3D RoPE); it takes pre-patchified tokens: our 2x2 patches."""
    from diffusers import LTXVideoTransformer3DModel

    d, heads = size["hidden_dim"], size["num_heads"]
    b, (c, t, h, w) = size["batch"], size["latent"]
    model = LTXVideoTransformer3DModel(
        in_channels=4 * c,
        out_channels=4 * c,
        num_attention_heads=heads,
        attention_head_dim=d // heads,
        cross_attention_dim=d,
        num_layers=size["depth"],
        caption_channels=TEXT_DIM,
    ).to(device)
    tokens = patchify(torch.randn(b, c, t, h, w), 2, 1).to(device)  # (B, N, 4c)
    text = torch.randn(b, TEXT_LEN, TEXT_DIM, device=device)
    mask, step = torch.ones(b, TEXT_LEN, device=device), torch.full((b,), 500, device=device)
    target = torch.randn_like(tokens)

    def loss():
        out = model(tokens, text, step, mask, num_frames=t, height=h // 2, width=w // 2, return_dict=False)[0]
        return F.mse_loss(out, target)

    return model, loss


def wan(size: dict, device: torch.device):
    """Wan 2.1 (cross-attention to text, 3D RoPE), FFN at 4x width as ours."""
    from diffusers import WanTransformer3DModel

    d, heads = size["hidden_dim"], size["num_heads"]
    b, (c, t, h, w) = size["batch"], size["latent"]
    model = WanTransformer3DModel(
        patch_size=(1, 2, 2),
        num_attention_heads=heads,
        attention_head_dim=d // heads,
        in_channels=c,
        out_channels=c,
        text_dim=TEXT_DIM,
        ffn_dim=4 * d,
        num_layers=size["depth"],
    ).to(device)
    latents = torch.randn(b, c, t, h, w, device=device)
    text, step = torch.randn(b, TEXT_LEN, TEXT_DIM, device=device), torch.full((b,), 500, device=device)
    target = torch.randn_like(latents)

    def loss():
        return F.mse_loss(model(latents, step, text, return_dict=False)[0], target)

    return model, loss


#: full_attn_every of the frame-local layout timed beside full attention: the small preset's
#: (studies/attention_layout.py compares their quality at equal compute).
FRAME_LOCAL_EVERY = dit_preset("small")["full_attn_every"]

MODELS: dict[str, Build] = {
    "drivewm DiT": ours,
    f"drivewm DiT, full every {FRAME_LOCAL_EVERY}": functools.partial(ours, full_attn_every=FRAME_LOCAL_EVERY),
    "CogVideoX": cogvideox,
    "LTX-Video": ltx,
    "Wan 2.1": wan,
}


def timed_step(model, loss_fn, opt, bf16: bool, device: torch.device) -> float:
    """Seconds of one training step (forward, loss, backward, AdamW): wall time on CUDA; on the CPU the
    process's CPU time, which other processes on a shared machine disturb far less than wall time
    (this benchmark runs its ops on the calling thread: one intra-op thread by default)."""
    if device.type == "cuda":
        torch.cuda.synchronize()
    clock = time.perf_counter if device.type == "cuda" else time.process_time
    tic = clock()
    with torch.autocast(device.type, dtype=torch.bfloat16, enabled=bf16):
        loss = loss_fn()
    loss.backward()
    opt.step()
    opt.zero_grad(set_to_none=True)
    if device.type == "cuda":
        torch.cuda.synchronize()
    return clock() - tic


def train_flops(params: int, tokens: int, depth: float, dim: int, batch: int) -> float:
    """6 x params x tokens + 12 x layers x (tokens per sample)^2 x width per sample (PaLM, app. B);
    ``depth``: blocks of full attention (a frame-local block at t latent frames counts 1/t)."""
    per_sample = tokens // batch
    return 6 * params * tokens + 12 * depth * per_sample**2 * dim * batch


def full_attention_depth(model: torch.nn.Module, size: dict) -> float:
    """Blocks of full attention the model's attention FLOPs equal: a frame-local block of drivewm's
    DiT attends over 1/t of the sequence; the peers' every block over all of it."""
    if not isinstance(model, EDMDenoiser):
        return size["depth"]
    cfg, t = model.backbone.cfg, size["latent"][1]
    return sum(1 / t if cfg.frame_local(i) else 1.0 for i in range(cfg.depth))


def peak_flops(device: torch.device, bf16: bool) -> float:
    """FLOP/s of one large square matmul (bf16 on CUDA, fp32 otherwise): the device's practical peak,
    timed with the clock of :func:`timed_step` (one call after a warm-up; :func:`compare` repeats it
    every round so the peak sees the same machine as the steps)."""
    n = 8192 if device.type == "cuda" else 2048
    dtype = torch.bfloat16 if bf16 else torch.float32
    a, b = torch.randn(n, n, device=device, dtype=dtype), torch.randn(n, n, device=device, dtype=dtype)
    clock = time.perf_counter if device.type == "cuda" else time.process_time
    a @ b
    if device.type == "cuda":
        torch.cuda.synchronize()
    tic = clock()
    a @ b
    if device.type == "cuda":
        torch.cuda.synchronize()
    return 2 * n**3 / (clock() - tic)


def tokens_of(size: dict) -> int:
    c, t, h, w = size["latent"]
    return size["batch"] * t * (h // 2) * (w // 2)


def compare(
    names: list[str], size: dict, rounds: int, device: torch.device, bf16: bool
) -> tuple[dict[str, tuple[int, list[float]]], float]:
    """Interleaved training steps of ``names`` -> ({name: (params, step seconds)}, median peak FLOP/s);
    the warm-up round is dropped, and the matmul peak is measured once per round beside the steps."""
    torch.manual_seed(0)
    runs = {name: MODELS[name](size, device) for name in names}
    # The same optimizer for every model: fused AdamW (one kernel; the per-tensor loop costs ~6x more).
    opts = {name: torch.optim.AdamW(m.parameters(), lr=1e-4, fused=True) for name, (m, _) in runs.items()}
    times, peaks = {name: [] for name in runs}, []
    for r in range(rounds + 1):  # round 0 warms up
        for name, (model, loss_fn) in runs.items():
            dt = timed_step(model, loss_fn, opts[name], bf16, device)
            if r:
                times[name].append(dt)
        peaks.append(peak_flops(device, bf16))
    params = {name: count_parameters(m) for name, (m, _) in runs.items()}
    depths = {name: full_attention_depth(m, size) for name, (m, _) in runs.items()}
    return {name: (params[name], depths[name], times[name]) for name in runs}, statistics.median(peaks)


def report(results: dict, peak: float, size: dict) -> None:
    print(f"peak by matmul {peak / 1e12:.3f} TFLOP/s (median over the rounds)")
    tokens = tokens_of(size)
    rate = {}
    for name, (params, depth, times) in results.items():
        step_s = statistics.median(times)
        rate[name] = tokens / step_s
        mfu = train_flops(params, tokens, depth, size["hidden_dim"], size["batch"]) / step_s / peak
        print(
            f"{name:26s} {params / 1e6:6.1f}M params  {step_s * 1e3:9.1f} ms/step (median of {len(times)}, "
            f"{min(times) * 1e3:.0f}-{max(times) * 1e3:.0f})  "
            f"{rate[name]:9.0f} tokens/s  MFU {mfu:6.1%}"
        )
    peers = [n for n in rate if not n.startswith("drivewm")]
    for ours_name in (n for n in rate if n.startswith("drivewm")):
        for name in peers:
            print(f"ratio {ours_name} / {name} tokens/s: {rate[ours_name] / rate[name]:.2f}")
        if peers:
            best = max(peers, key=rate.get)
            print(f"ratio {ours_name} / best peer ({best}) tokens/s: {rate[ours_name] / rate[best]:.2f}")


#: Op classes of the --profile table: aten op names (attention is told apart by name, see :func:`op_class`).
OP_CLASSES = {
    "GEMM (linear fwd/bwd)": {"mm", "addmm", "bmm"},
    "GELU fwd/bwd": {"gelu", "gelu_backward"},
    "norms": {"native_layer_norm", "native_layer_norm_backward", "pow", "rsqrt", "mean"},
    "layout copies": {"copy_", "cat", "clone", "stack"},
    "reductions (bias/gate grads)": {"sum"},
    "elementwise (modulation, RoPE, loss)": {"mul", "mul_", "add", "add_", "addcmul", "sub", "div", "div_", "neg"},
    "optimizer": {"_fused_adamw_"},
}


def op_class(name: str) -> str:
    """The op class of an aten op's profiler name: attention fwd/bwd, an :data:`OP_CLASSES` key, or other."""
    if "scaled_dot_product" in name or "flash_attention" in name:
        return "attention bwd" if "backward" in name else "attention fwd"
    op = name.removeprefix("aten::")
    return next((cls for cls, ops in OP_CLASSES.items() if op in ops), "other")


def profile_step(names: list[str], size: dict, device: torch.device) -> None:
    """Print, per model, the share of one training step's time in each op class (torch.profiler: self time
    of the aten ops, on the CPU or the GPU, after one warm step). Shares, as the profiler's own overhead
    and clock differ from :func:`timed_step`'s."""
    from torch.profiler import ProfilerActivity, profile

    cuda = device.type == "cuda"
    for name in names:
        torch.manual_seed(0)
        model, loss_fn = MODELS[name](size, device)
        opt = torch.optim.AdamW(model.parameters(), lr=1e-4, fused=True)
        timed_step(model, loss_fn, opt, cuda, device)
        with profile(activities=[ProfilerActivity.CUDA if cuda else ProfilerActivity.CPU]) as prof:
            timed_step(model, loss_fn, opt, cuda, device)
        by_class: dict[str, float] = {}
        for event in prof.key_averages():
            spent = event.self_device_time_total if cuda else event.self_cpu_time_total
            by_class[op_class(event.key)] = by_class.get(op_class(event.key), 0.0) + spent
        total = sum(by_class.values())
        shares = ", ".join(f"{cls} {t / total:.1%}" for cls, t in sorted(by_class.items(), key=lambda kv: -kv[1]))
        print(f"profile {name}: {shares}")


def load_note(threads: int) -> str:
    """'under load' when other processes keep the CPUs busy (1-minute load average above our threads)."""
    load = os.getloadavg()[0]
    busy = load > threads + 0.5
    return f"{'under load' if busy else 'idle machine'} (load average {load:.1f} on {os.cpu_count()} CPUs)"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="small", choices=sorted(SIZES), help="model and sequence size")
    parser.add_argument("--rounds", type=int, default=5, help="timed steps per model")
    parser.add_argument("--threads", type=int, default=1, help="CPU intra-op threads")
    parser.add_argument("--models", nargs="+", default=list(MODELS), choices=list(MODELS), help="what to compare")
    parser.add_argument(
        "--mfu-size", choices=sorted(SIZES), help="also time our DiT alone at this size for MFU (default: base on CUDA)"
    )
    parser.add_argument(
        "--mfu-batch", type=int, help="samples per step of the MFU run (default: 16 on CUDA, the size's on the CPU)"
    )
    parser.add_argument("--profile", action="store_true", help="also print each model's step time per op class")
    args = parser.parse_args()
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    torch.set_num_threads(args.threads)
    bf16 = device.type == "cuda"
    size = SIZES[args.size]
    print(
        f"device {device} ({'bf16 autocast' if bf16 else 'fp32'}, {args.threads} thread(s), {load_note(args.threads)})"
    )
    print(
        f"size {args.size}: batch {size['batch']} x {tokens_of(size) // size['batch']} tokens, "
        f"D={size['hidden_dim']}, depth {size['depth']}, {size['num_heads']} heads"
    )
    report(*compare(args.models, size, args.rounds, device, bf16), size)
    if args.profile:
        profile_step(args.models, size, device)
    mfu_size = args.mfu_size or ("base" if device.type == "cuda" else None)
    if mfu_size:
        big = dict(SIZES[mfu_size], batch=args.mfu_batch or (16 if device.type == "cuda" else SIZES[mfu_size]["batch"]))
        print(
            f"MFU at {mfu_size}: batch {big['batch']} x {tokens_of(big) // big['batch']} tokens, D={big['hidden_dim']}"
        )
        report(*compare(["drivewm DiT"], big, args.rounds, device, bf16), big)
    print(f"end: {load_note(args.threads)}")


if __name__ == "__main__":
    main()
