"""Time of one ``drivewm transfer`` clip with the transfer's look shared between cameras (the default,
drivewm.transfer.detail.share_look) against each view's own (``--no-shared-look``), end to end as the
command runs it: the source coded, the network's steps, decode, upsampling, detail, clip built.

The shipped transfer model (or ``--model``), 8 Euler steps, a simulated 6-camera clip of ``--clips``
(the first one; 320x192 as the simulator renders, or any size: ``--size 1600x900`` resizes it, as a
fleet rig's cameras are). The two settings alternate, ``--repeats`` times each after one warm-up
round, and the medians are compared: the printed ratio is the shared look's time over the own
look's. Both are measured in the same run, so a busy machine slows both alike (say so when quoting it).

    python benchmarks/bench_transfer_look.py --clips TRANSFER_HELDOUT_CLIPS_320
    python benchmarks/bench_transfer_look.py --clips TRANSFER_HELDOUT_CLIPS_320 --size 1600x900 --repeats 2
"""

from __future__ import annotations

import argparse
import dataclasses

import torch
from interleaved import alternate, print_medians

from drivewm.clips import iter_clips
from drivewm.clips.format import clip_from_arrays
from drivewm.model_folders import resolve_model_folder
from drivewm.multiview.coding import resize_views
from drivewm.train.checkpoint import load_model_folder
from drivewm.transfer.apply import TransferOptions, load_tokenizer, load_transferer, transfer_clip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="shipped:transfer")
    parser.add_argument("--clips", required=True, help="a curated clip folder (6 cameras, the model's frames)")
    parser.add_argument("--size", default=None, help="WxH to resize the clip to (default: its own)")
    parser.add_argument("--repeats", type=int, default=3, help="clips per setting, alternating")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    clip = next(iter_clips(args.clips))
    if args.size:
        w, h = (int(v) for v in args.size.lower().split("x"))
        videos = resize_views(clip.videos(), (h, w))
        rig = clip.meta.get_rig().scaled(w, h, fit="stretch")
        meta = dataclasses.replace(clip.meta, rig=rig.to_dict())
        clip = clip_from_arrays(meta, dict(zip(rig.names, videos)), clip.T_world_from_ego)
    v, t, h, w, _ = clip.videos().shape
    folder = resolve_model_folder(args.model)
    _, state = load_model_folder(folder, "transfer")
    params = sum(p.numel() for p in state.values() if p.is_floating_point())
    print(f"{args.model}: {params / 1e6:.2f}M parameters; {v} cameras x {t} frames at {w}x{h}, 8 Euler steps")
    options = TransferOptions("snow")
    transferer = load_transferer(folder, options)  # the network's settings; the look is transfer_clip's
    tokenizer = load_tokenizer(transferer.latent.tokenizer, folder)

    def run(shared: bool):
        def one(r: int) -> None:
            transfer_clip(clip, transferer, tokenizer, dataclasses.replace(options, seed=r, shared_look=shared))

        return one

    times = alternate({"own": run(False), "shared": run(True)}, args.repeats)
    print_medians(times, "own", "look")


if __name__ == "__main__":
    main()
