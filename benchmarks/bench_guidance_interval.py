"""Sampling time of one multi-view clip with guidance at every step against guidance in a limited
interval of noise levels (``drivewm generate --guidance-interval``; Kynkaenniemi et al. 2024).

The shipped multi-view model (or ``--model``), the world-model benchmark's sampler settings (20 Heun
steps, guidance 7, nuscenes6, a left turn), one clip at a time as ``drivewm generate`` samples them.
The two settings alternate, ``--repeats`` times each, and the medians are compared: the printed ratio
is interval time over plain time, beside the network evaluations each one counts. Both are measured
in the same run, so a busy machine slows both alike (say so when quoting it).

    python benchmarks/bench_guidance_interval.py                       # shipped model, (0.28, 5.42]
    python benchmarks/bench_guidance_interval.py --interval 0.2,10 --steps 35 --repeats 5
"""

from __future__ import annotations

import argparse

import torch
from interleaved import add_sampling_arguments, alternate, print_medians

from drivewm.choices import sigma_interval
from drivewm.generate.captions import view_captions
from drivewm.model_folders import resolve_model_folder
from drivewm.multiview.model import MultiView
from drivewm.multiview.trajectories import resolve_trajectory


class Counted(torch.nn.Module):
    """The model's network, counting the clips it denoises (one per view-folded batch call)."""

    def __init__(self, net: torch.nn.Module):
        super().__init__()
        self.net, self.calls = net, 0

    def forward(self, x, sigma, cond):
        self.calls += 1
        return self.net(x, sigma, cond)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_sampling_arguments(parser)
    parser.add_argument("--interval", type=sigma_interval, default=(0.28, 5.42), help="LO,HI (default 0.28,5.42)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    model = MultiView.from_pretrained(resolve_model_folder(args.model))
    counted = Counted(model.net)
    model.net = counted
    mv, rig = model.cfg.multiview, model.training_rig
    waypoints = resolve_trajectory("left", mv.trajectory_waypoints, mv.trajectory_dt_s, mv.speed_mps)[None]
    captions = [view_captions("light snow on a country lane, turning left", rig)]
    params = sum(p.numel() for p in counted.net.parameters())
    shape = model.latent.latent_shape
    print(f"{args.model}: {params / 1e6:.2f}M parameters, {len(rig.cameras)} views, latents {shape}")
    print(f"{args.steps} Heun steps, guidance {args.guidance:g}, {torch.get_num_threads()} threads")
    settings = {"every step": None, f"({args.interval[0]:g}, {args.interval[1]:g}]": args.interval}
    evals: dict[str, int] = {}

    def run(name: str, interval):
        def sample(r: int) -> None:
            counted.calls = 0
            model.sample_latents(rig, captions, waypoints, [r], args.steps, args.guidance, guidance_interval=interval)
            evals[name] = counted.calls

        return sample

    times = alternate({name: run(name, interval) for name, interval in settings.items()}, args.repeats)
    print_medians(times, "every step", "guidance", {"evals": evals})


if __name__ == "__main__":
    main()
