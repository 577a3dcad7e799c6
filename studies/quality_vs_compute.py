"""Quality against compute spent, for each model of a ``drivewm worldmodel train`` run.

Reads the run's own training logs (``metrics.jsonl`` of tokenizer/, text2world_image/, text2world/,
multiview/) and evals; writes a figure and prints a table. The tokenizer panel fits the training
PSNR against log10(steps) after the first tenth of the run and prints the step count at which the
fit reaches the 32 dB goal -- a prediction, labelled as one: a small model's PSNR flattens (at a
constant learning rate it plateaus, see the figure), so the fit is optimistic beyond the data.

    python studies/quality_vs_compute.py RUN --out docs/figures/quality_vs_compute.png \
        --samples docs/figures/shipped_samples.jpg

``--samples`` also stacks the contact sheets of a few benchmark prompts (RUN/generated/NAME/),
half size, into one picture.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from drivewm.atomic import read_jsonl  # noqa: E402

STAGES = (("tokenizer", "tokenizer"), ("text2world_image", "Text2World, images"),
          ("text2world", "Text2World, video"), ("multiview", "multi-view"))  # fmt: skip
PSNR_GOAL_DB = 32.0


def smooth(values: np.ndarray, window: int = 9) -> np.ndarray:
    """Running median (training losses of small batches are noisy)."""
    half = window // 2
    return np.array([np.median(values[max(0, i - half) : i + half + 1]) for i in range(len(values))])


def psnr_fit(steps: np.ndarray, psnr: np.ndarray) -> tuple[float, float]:
    """PSNR ~ a + b log10(step) after the first tenth of the run; returns (a, b)."""
    keep = steps >= steps.max() / 10
    b, a = np.polyfit(np.log10(steps[keep]), psnr[keep], 1)
    return float(a), float(b)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--out", type=Path, default=Path("quality_vs_compute.png"))
    ap.add_argument("--samples", type=Path, help="also write the benchmark prompts' contact sheets here")
    args = ap.parse_args()
    fig, axes = plt.subplots(1, len(STAGES), figsize=(4.2 * len(STAGES), 3.4))
    print("| model | steps | wall hours | last loss (median of 9 logs) |")
    print("|---|---|---|---|")
    for ax, (folder, title) in zip(axes, STAGES, strict=True):
        log = [r for r in read_jsonl(args.run / folder / "metrics.jsonl") if "loss" in r]
        ax.set_title(title)
        if not log:
            ax.text(0.5, 0.5, "not trained", ha="center", transform=ax.transAxes)
            continue
        steps = np.array([r["step"] for r in log], dtype=float)
        hours = log[-1].get("train_seconds", float("nan")) / 3600
        if folder == "tokenizer" and "psnr" in log[0]:
            psnr = smooth(np.array([r["psnr"] for r in log]))
            ax.plot(steps, psnr, label="training-crop PSNR (running median)")
            a, b = psnr_fit(steps, psnr)
            ext = np.geomspace(steps.max() / 10, steps.max() * 30, 50)
            ax.plot(ext, a + b * np.log10(ext), "--", label=f"fit {a:.1f} + {b:.2f} log10(step)")
            ax.axhline(PSNR_GOAL_DB, color="k", lw=0.8, label="32 dB goal")
            ax.set_xscale("log")
            ax.set_ylabel("dB")
            reach = 10 ** ((PSNR_GOAL_DB - a) / b) if b > 0 else float("inf")
            print(f"tokenizer: the fit reaches {PSNR_GOAL_DB:.0f} dB at ~{reach:,.0f} steps (a prediction)")
            ax.legend(fontsize=7)
        else:
            loss = smooth(np.array([r["loss"] for r in log]))
            ax.plot(steps, loss)
            ax.set_ylabel("denoising loss (running median)")
        ax.set_xlabel("step")
        print(f"| {title} | {int(steps.max())} | {hours:.2f} | {smooth(np.array([r['loss'] for r in log]))[-1]:.4f} |")
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")
    if args.samples:
        stack_sheets(args.run / "generated", SAMPLE_SHEETS, args.samples)


#: Benchmark prompts whose contact sheets --samples stacks.
SAMPLE_SHEETS = ("clear_straight", "fog_straight", "night_straight", "snow_left", "rain_right")


def stack_sheets(generated: Path, names: tuple[str, ...], out: Path) -> None:
    from PIL import Image

    sheets = [Image.open(generated / n / "contact_sheet.png").convert("RGB") for n in names]
    stack_images([s.resize((s.width // 2, s.height // 2)) for s in sheets], out)


def stack_images(images: list, out: Path) -> None:
    """PIL ``images`` one above the other, left-aligned on white, written to ``out``."""
    from PIL import Image

    canvas = Image.new("RGB", (max(i.width for i in images), sum(i.height for i in images)), "white")
    y = 0
    for image in images:
        canvas.paste(image, (0, y))
        y += image.height
    out.parent.mkdir(parents=True, exist_ok=True)
    canvas.save(out, quality=85)  # a JPEG: samples are photographs, a PNG of them is megabytes
    print(f"wrote {out} ({canvas.width}x{canvas.height})")


if __name__ == "__main__":
    main()
