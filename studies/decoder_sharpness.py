"""How sharp does each tokenizer decode held-out clips, next to the clips themselves?

A decoder fitted to pixel losses alone draws the mean of what a latent could be: blur. Structure from
motion and the Sampson errors need corners, so a sharper decoder (an adversarial term, as Cosmos'
and Stable Diffusion's autoencoders add last) could lift the geometry figures without any change
to the diffusion models. This study measures what each decoder gives back, every ``--every``-th
held-out clip, every camera, every 4th frame: the mean absolute Laplacian (edge energy) and the
SIFT keypoints OpenCV finds, beside the raw clips; ``--figure`` writes the front camera of one clear,
one snow and one fog clip, raw and through each tokenizer (frame 8, twice the size).

    python studies/decoder_sharpness.py HELDOUT_CLIPS before=TOK_A now=shipped:tokenizer adv=TOK_B \\
        [--every 8] [--figure docs/figures/decoder_sharpness.jpg]

Numbers: git show a88b7a4:docs/quality-vs-compute.md, "The decoder's learning rate decayed".
"""

from __future__ import annotations

import argparse
import itertools

import cv2
import numpy as np
import torch

from drivewm.clips.shards import iter_clips
from drivewm.multiview.coding import code_views
from drivewm.tokenizer import Tokenizer
from drivewm.transfer.retarget import TargetCondition

FIGURE_CONDITIONS = ("clear:day", "snow:day", "fog:day")


def sharpness(video: np.ndarray, sift: cv2.SIFT) -> tuple[float, float]:
    """(mean |Laplacian|, mean SIFT keypoints) over every camera and every 4th frame of uint8 (V, T, H, W, 3)."""
    frames = [video[v, t] for v in range(video.shape[0]) for t in range(0, video.shape[1], 4)]
    grays = [cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) for f in frames]
    edges = np.mean([np.abs(cv2.Laplacian(g.astype(np.float32), cv2.CV_32F)).mean() for g in grays])
    return float(edges), float(np.mean([len(sift.detect(g, None)) for g in grays]))


def condition(clip) -> str | None:
    """WEATHER:TIME of a clip's tags (None when they name none)."""
    cond = TargetCondition.of(clip.meta)
    return cond.name if cond is not None else None


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("clips")
    p.add_argument("tokenizers", nargs="+", help="LABEL=FOLDER (or shipped:tokenizer)")
    p.add_argument("--every", type=int, default=8)
    p.add_argument("--figure", help="write the contact sheet here")
    args = p.parse_args()
    torch.set_num_threads(1)
    toks = {}
    for arg in args.tokenizers:
        label, folder = arg.split("=", 1)
        toks[label] = Tokenizer.from_pretrained(folder)  # shipped:tokenizer resolves there
    sift = cv2.SIFT_create()
    stats: dict[str, list] = {k: [] for k in ["raw", *toks]}
    for clip in itertools.islice(iter_clips(args.clips), 0, None, args.every):
        video = clip.videos()
        stats["raw"].append(sharpness(video, sift))
        for label, tok in toks.items():
            stats[label].append(sharpness(code_views(tok, video, video.shape[2:4], "cpu"), sift))
    print("| decoded by | clips | mean abs Laplacian | SIFT keypoints per frame |")
    print("|---|---|---|---|")
    for label, rows in stats.items():
        a = np.array(rows)
        print(f"| {label} | {len(a)} | {a[:, 0].mean():.2f} | {a[:, 1].mean():.1f} |")
    if args.figure:
        write_figure(args.clips, toks, args.figure)


def write_figure(clips: str, toks: dict, path: str) -> None:
    rows, wanted = [], list(FIGURE_CONDITIONS)
    for clip in iter_clips(clips):
        if condition(clip) not in wanted:
            continue
        wanted.remove(condition(clip))
        front = clip.videos()[:1]
        cells = [("simulator", front)] + [(k, code_views(t, front, front.shape[2:4], "cpu")) for k, t in toks.items()]
        row = []
        for label, video in cells:
            img = cv2.resize(video[0, 8], None, fx=2, fy=2, interpolation=cv2.INTER_NEAREST)[..., ::-1].copy()
            text = f"{label} ({condition(clip)})"
            cv2.putText(img, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (0, 255, 255), 1, cv2.LINE_AA)
            row.append(img)
        rows.append(np.hstack(row))
        if not wanted:
            break
    cv2.imwrite(path, np.vstack(rows), [cv2.IMWRITE_JPEG_QUALITY, 88])
    print(f"figure: {path}")


if __name__ == "__main__":
    main()
