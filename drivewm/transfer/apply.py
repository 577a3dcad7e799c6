"""``drivewm transfer``: clips in, the same clips in another weather / time of day out.

Every clip is resized to the model's image size, coded by the tokenizer, transferred view by view
(a transfer model folder, or SDEdit with a Text2World folder as the baseline), decoded, brought back
to the source's size with its detail (drivewm.transfer.resolution; ``model_resolution`` writes the
model's size instead, as before) and written as a clip (``OUT/transferred-NNNNNN.tar`` +
``manifest.jsonl``) that keeps every label of the source: timestamps, rig (the source's, or scaled to
the model's size), ego poses, trajectory, pair id and the other tags; the weather / time-of-day tags
and captions are the target's (drivewm.transfer.retarget).
Beside them: ``sheets/KEY.png`` (source above, transferred below, six frames over time) and
``contact_sheet.png``. A clip that cannot be transferred is reported and skipped; none transferred is
a BatchError (exit 2), as in curate and encode.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from drivewm.atomic import write_json
from drivewm.clips.format import Clip, clip_from_arrays
from drivewm.clips.shards import ShardWriter, iter_shard, list_shards, write_manifest
from drivewm.config import finite_at_least
from drivewm.curate.stage import manifest_row
from drivewm.diffusion.generate import write_grid_png
from drivewm.diffusion.text2world import LatentInfo
from drivewm.errors import BatchError, DrivewmError
from drivewm.generate.config import SamplingConfig
from drivewm.logs.types import TIMES_OF_DAY
from drivewm.multiview.coding import decode_views, encode_views, resize_views
from drivewm.train.checkpoint import read_model_config
from drivewm.transfer.detail import BAND_PX
from drivewm.transfer.resolution import output_size_hw, rig_at_size, to_output_size
from drivewm.transfer.retarget import TargetCondition, retarget_meta, target_captions
from drivewm.views.grid import grid_layout, tile_views

SHEET_CLIPS = 3  # clips shown in contact_sheet.png


@dataclasses.dataclass
class TransferOptions:
    """Settings of ``drivewm transfer``."""

    weather: str
    """Target weather (clear | overcast | rain | snow | fog)."""
    time_of_day: str | None = None
    """Target time of day (day | dusk | night); None keeps each clip's own (day when unknown)."""
    sampling: SamplingConfig = dataclasses.field(default_factory=lambda: SamplingConfig(8, "euler", 1.0))
    """Sampler steps, sampler and classifier-free guidance on the target condition (generation's
    SamplingConfig; here 8 Euler steps, guidance 1 = none); view v of every clip draws its noise
    from seed + v. Its trajectory settings have no use in a transfer."""
    start_sigma: float | None = None
    """Transfer model: start from the source noised to this sigma (None: from pure noise). SDEdit
    (a Text2World model): the noise level the source is lifted to (required)."""
    tokenizer: str | None = None
    """Tokenizer folder; None = the one recorded in the model folder."""
    device: str = "cpu"
    """Where the networks run: ``auto`` (CUDA when available), ``cpu`` or ``cuda``."""
    max_clips: int | None = None
    """Transfer only the first N clips of the inputs (a preview; None: all)."""
    detail: bool = True
    """Add back the source detail the tokenizer drops, scaled by the contrast the target keeps
    (drivewm.transfer.detail); False writes the decoded transfer as it is (upsampled)."""
    detail_band: float = BAND_PX
    """Model pixels: the source's structure finer than a Gaussian of this sigma replaces the transfer's
    (drivewm.transfer.detail; 0: only the detail the tokenizer dropped, as before the band)."""
    shared_look: bool = True
    """Share the transfer's look (its light, colour and haze coarser than the detail band, and its
    contrast gain) between cameras where they see one point of the flat world, so two cameras of one
    scene get one look where they overlap (drivewm.transfer.detail.share_look); the source's structure
    stays each view's own. False: each view on its own."""
    model_resolution: bool = False
    """Write clips at the model's image size, the rig scaled to it; False (default) keeps the source's
    size and rig when the source is larger (drivewm.transfer.resolution)."""

    def validate(self) -> None:
        s = self.sampling
        if s.steps < 1 or (self.max_clips is not None and self.max_clips < 1):
            raise DrivewmError(f"transfer: --steps ({s.steps}) and --max-clips ({self.max_clips}) must be >= 1")
        # checked here, not per clip: a bad value would fail every clip of every shard, one after another
        finite_at_least("transfer", 0, **{"--guidance": s.guidance, "--detail-band": self.detail_band})
        try:
            s.validate()
        except DrivewmError as exc:
            raise DrivewmError(f"transfer: {exc}") from None
        if self.start_sigma is not None and not (math.isfinite(self.start_sigma) and self.start_sigma > 0):
            raise DrivewmError(f"transfer: --start-sigma must be a finite number > 0, got {self.start_sigma}")

    def is_done(self, written: int) -> bool:
        """True once ``written`` clips reach ``max_clips``."""
        return self.max_clips is not None and written >= self.max_clips

    def target_for(self, clip: Clip) -> TargetCondition:
        """The target of one clip: the weather asked for, the time asked for or the clip's own."""
        own = clip.meta.tags.get("time_of_day")
        target = TargetCondition(self.weather, self.time_of_day or (own if own in TIMES_OF_DAY else "day"))
        target.validate()
        return target


@dataclasses.dataclass
class Transferer:
    """A loaded model as one call: ``fn(raw source latents (B, c, t, h, w), captions, targets, seeds)``."""

    fn: object
    latent: LatentInfo
    record: dict  # what the output clips record in extra["transfer"]
    device: torch.device = torch.device("cpu")  # where the model runs (the tokenizer joins it)


def load_transferer(model_dir: str | Path, options: TransferOptions) -> Transferer:
    """A transfer model folder, or a Text2World folder run as SDEdit (needs ``options.start_sigma``)."""
    model_dir = Path(model_dir)
    model_type = read_model_config(model_dir).get("model_type")
    o, s = options, options.sampling
    record = {"model": str(model_dir.resolve()), "steps": s.steps, "guidance": s.guidance, "sampler": s.sampler}
    record |= {"seed": s.seed, "start_sigma": o.start_sigma, "detail": o.detail, "detail_band": o.detail_band}
    record |= {"model_resolution": o.model_resolution, "shared_look": o.detail and o.shared_look}
    if model_type == "transfer":
        from drivewm.transfer.model import Transfer

        model = Transfer.from_pretrained(model_dir).to(o.device)

        def fn(src, captions, targets, seeds):
            return model.transfer_latents(src, captions, targets, seeds, s.steps, s.guidance, s.sampler, o.start_sigma)

        return Transferer(fn, model.latent, {**record, "method": "transfer"}, model.device)
    if model_type == "text2world":
        from drivewm.diffusion.text2world import Text2World
        from drivewm.transfer.sdedit import sdedit_latents

        if not o.start_sigma:
            raise DrivewmError(f"{model_dir}: a Text2World model transfers by SDEdit and needs --start-sigma")
        t2w = Text2World.from_pretrained(model_dir).to(o.device)

        def fn(src, captions, targets, seeds):
            return sdedit_latents(t2w, src, captions, seeds, o.start_sigma, s.steps, s.guidance, s.sampler)

        return Transferer(fn, t2w.latent, {**record, "method": "sdedit"}, t2w.device)
    raise DrivewmError(f"{model_dir}: cannot transfer with model_type {model_type!r} (transfer or text2world)")


def load_tokenizer(path: str | None, model_dir: str | Path, device: torch.device | str = "cpu"):
    from drivewm.tokenizer import Tokenizer

    if not path:
        raise DrivewmError(f"{model_dir}: no tokenizer recorded in the model folder; give --tokenizer")
    return Tokenizer.from_pretrained(path).to(device)


@torch.no_grad()
def transfer_clip(clip: Clip, transferer: Transferer, tokenizer, options: TransferOptions) -> tuple[Clip, np.ndarray]:
    """(the transferred clip, the source frames at its size uint8 (V, T, H, W, 3))."""
    c, t, h, w = transferer.latent.latent_shape
    tc, sc = tokenizer.config.temporal_compression, tokenizer.config.spatial_compression
    frames = 1 + (t - 1) * tc
    if clip.meta.num_frames != frames:
        raise DrivewmError(
            f"clip {clip.key}: {clip.meta.num_frames} frames; this model transfers {frames}-frame clips "
            f"(curate with clip_frames: {frames})"
        )
    target = options.target_for(clip)
    model_hw = (h * sc, w * sc)
    full = clip.videos()
    out_hw = output_size_hw(full.shape[2:4], model_hw, options.model_resolution)
    small = resize_views(full, model_hw)  # (V, T, H, W, 3) at the model's size, as the curator resizes
    source = encode_views(tokenizer, small, model_hw, transferer.device)  # (V, c, t, h, w) on the CPU
    _, views = target_captions(clip.meta, target)
    captions = [views[name] for name in clip.meta.cameras]
    seeds = [options.sampling.seed + v for v in range(len(captions))]
    out = decode_views(tokenizer, transferer.fn(source, captions, [target] * len(captions), seeds), transferer.device)
    shown = resize_views(full, out_hw)  # the source at the output size: the detail's reference and the sheet's
    coded = decode_views(tokenizer, source, transferer.device) if options.detail else None
    look_rig = clip.meta.get_rig() if options.shared_look else None  # at any size: the grid is the frames'
    out = to_output_size(out, shown, coded, options.detail_band, rig=look_rig)
    rig, meta = rig_at_size(clip.meta.get_rig(), full.shape[2:4], out_hw), clip.meta
    if out_hw != full.shape[2:4]:
        meta = dataclasses.replace(meta, rig=rig.to_dict())
    meta = retarget_meta(meta, target, f"{clip.key}-{target.weather}-{target.time_of_day}", transferer.record)
    return clip_from_arrays(meta, dict(zip(rig.names, out)), clip.T_world_from_ego), shown


def transfer_clips(
    model_dir: str | Path, inputs: list[str | Path], options: TransferOptions, out_dir: str | Path
) -> dict:
    """Transfer every clip of ``inputs`` (shards or clip folders; the first ``options.max_clips``) into
    ``out_dir``; returns the report (also ``report.json``): clips written, and clips or shards skipped
    with the reason. No clip written raises :class:`BatchError` (after writing the report) with one line
    per skipped clip or shard."""
    options.validate()
    transferer = load_transferer(model_dir, options)
    tokenizer = load_tokenizer(options.tokenizer or transferer.latent.tokenizer, model_dir, transferer.device)
    out = Path(out_dir)
    (out / "sheets").mkdir(parents=True, exist_ok=True)
    rows, failed, sheet = [], [], []
    with ShardWriter(out, "transferred") as writer:
        for shard in tqdm(list_shards(inputs), desc="transfer", unit="shard"):
            if options.is_done(len(rows)):
                break
            try:
                for clip in iter_shard(shard):
                    if options.is_done(len(rows)):
                        break
                    try:
                        result, source = transfer_clip(clip, transferer, tokenizer, options)
                    except DrivewmError as exc:
                        failed.append({"clip": clip.key, "shard": str(shard), "error": str(exc)})
                        continue
                    writer.write(result)
                    rows.append(manifest_row(result.meta))
                    sheet += _write_sheet(out / "sheets" / f"{result.key}.png", source, result)
            except DrivewmError as exc:  # a corrupt shard costs its clips, not the run
                failed.append({"shard": str(shard), "error": str(exc)})
    shard_of = {key: name for name, key in writer.written}
    for row in rows:
        row["shard"] = shard_of[row["key"]]
    write_manifest(out, rows)
    if sheet:
        captions = [text for _, _, text in sheet[: 2 * SHEET_CLIPS]]
        write_grid_png(np.stack([v for _, v, _ in sheet[: 2 * SHEET_CLIPS]]), out / "contact_sheet.png", captions)
    report = {"written": [r["key"] for r in rows], "failed": failed, **transferer.record}
    write_json(out / "report.json", report)
    if not rows:  # as curate and encode: a run that wrote nothing is an error, with every reason
        lines = [f"{f.get('clip', f['shard'])}: {f['error']}" for f in failed] or ["no clips found"]
        raise BatchError(f"transfer: no clip transferred ({len(failed)} skipped; {out / 'report.json'})", lines)
    return report


def _write_sheet(path: Path, source: np.ndarray, result: Clip) -> list[tuple[str, np.ndarray, str]]:
    """Side-by-side sheet of one clip (rig mosaics over time: source row, transferred row); returns its rows."""
    layout = grid_layout(result.meta.get_rig())
    info = result.meta.extra["transfer"]
    src = info["source"]
    rows = [
        (result.key, tile_views(source, layout), f"{src['key']}: {src['weather']}/{src['time_of_day']}"),
        (result.key, tile_views(result.videos(), layout), f"{result.key}: {info['target']}"),
    ]
    write_grid_png(np.stack([r[1] for r in rows]), path, [r[2] for r in rows])
    return rows
