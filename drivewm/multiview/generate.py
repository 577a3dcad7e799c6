"""Multi-view generation: a prompt, a rig and a trajectory -> clips of all cameras (clip format),
grid videos and a contact sheet. ``drivewm generate`` dispatches here for ``model_type: multiview``.

With ``--condition-clip`` the first frames of every view come from a real clip (Video2World) and
the clip's rig calibration is used; without it, everything is generated.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from drivewm.curate.captions import camera_direction, classify_manoeuvre, prompt_view_captions
from drivewm.diffusion.generate import GenerateOptions, decode_latents, warn_if_preview
from drivewm.errors import DrivewmError
from drivewm.geometry import Rig, load_rig
from drivewm.multiview.blend import blend_overlaps, stitch_views
from drivewm.multiview.coding import decode_views, encode_views
from drivewm.multiview.defaults import DEFAULT_STITCH
from drivewm.multiview.model import MultiView
from drivewm.multiview.reproject import Reprojection, refine_reprojected
from drivewm.multiview.rollout import clip_rig, initial_speed_mps, load_clip
from drivewm.multiview.trajectories import resolve_trajectory
from drivewm.multiview.writer import GeneratedSample, write_samples
from drivewm.text.conditions import named_values
from drivewm.tokenizer import Tokenizer

#: What a prompt that names no time of day is completed with: the captioner's own phrase for daylight.
DEFAULT_TIME_PHRASE = "during the day"


def view_captions(prompt: str, rig: Rig) -> list[str]:
    """Per-view captions in the curated clips' form ("The front-left camera view of ..."), unless
    the prompt already names a camera view (then it is every view's caption as it is).

    Every caption the models train on names its time of day (drivewm.curate.captions), so a prompt
    that names none ("steady rain on the motorway") left the model between day, dusk and night, and
    rain came out as a dark, night-like blur; such a prompt asks for daylight, as a driver would read
    it, and is completed with :data:`DEFAULT_TIME_PHRASE` (docs/quality-vs-compute.md, "A prompt that
    names no time of day"). The eval still scores only what the prompt itself names."""
    if "camera view" in prompt:
        return [prompt] * len(rig.cameras)
    scene = prompt.strip().rstrip(".")
    scene = scene[:1].lower() + scene[1:]
    if not named_values(scene, "time_of_day"):
        scene = f"{scene}, {DEFAULT_TIME_PHRASE}"
    return [f"The {camera_direction(c)} camera view of {scene}." for c in rig.cameras]


def template_view_captions(prompt: str, rig: Rig, waypoints: np.ndarray, dt_s: float) -> list[str]:
    """``prompt`` rewritten into the curated clips' own template (``--prompt-template``;
    drivewm.curate.captions.prompt_view_captions), its manoeuvre and speed those of ``waypoints``
    (W, 3) m, spaced ``dt_s`` from the ego's first position, as the captioner reads a logged clip's."""
    xyz = np.vstack([np.zeros((1, 3)), np.asarray(waypoints, dtype=np.float64)])
    step = np.diff(xyz[:, :2], axis=0)
    speed = np.linalg.norm(step, axis=1) / dt_s
    yaw = np.unwrap(np.arctan2(step[:, 1], step[:, 0]))
    manoeuvre = classify_manoeuvre(xyz, np.concatenate([yaw[:1], yaw]), np.concatenate([speed[:1], speed]))
    return prompt_view_captions(prompt, rig.cameras, manoeuvre, float(speed.mean()))


def condition_latents(model: MultiView, clip_path: Path, rig: Rig | None) -> tuple[torch.Tensor, Rig, float]:
    """Raw latents (1, V, c, t, h, w) of a real clip's first frames (Video2World), its rig, its speed."""
    if not model.latent.tokenizer:
        raise DrivewmError(
            f"{clip_path}: conditioning on a clip needs the model's tokenizer (none recorded in the model folder)"
        )
    tokenizer = Tokenizer.from_pretrained(model.latent.tokenizer).to(model.device)
    clip = load_clip(clip_path)
    rig = clip_rig(model, clip) if rig is None else clip.meta.get_rig().subset(rig.names)
    c, t, h, w = model.latent.latent_shape
    sc, tc = tokenizer.config.spatial_compression, tokenizer.config.temporal_compression
    frames = np.stack([clip.video(n)[: 1 + (t - 1) * tc] for n in rig.names])
    z = encode_views(tokenizer, frames, (h * sc, w * sc), model.device)
    return z[None], rig, initial_speed_mps(clip)


def generate_multiview(
    model_dir: str | Path,
    options: GenerateOptions,
    rig_spec: str | None,
    trajectory: str | None,
    condition_clip: str | Path | None,
    out_dir: str | Path,
    trajectory_guidance: float = 1.0,
    reprojection: Reprojection | None = None,
    prompt_template: bool = True,
    stitch: bool | None = None,
) -> list[Path]:
    """``options.num_samples`` clips per prompt for ``rig_spec`` (default: the training rig) under
    ``trajectory`` (default straight) and write them (drivewm.multiview.writer); with a
    ``reprojection`` sigma (default ``DEFAULT_SIGMA`` where the model has a tokenizer:
    ``Reprojection.resolved``; ``Reprojection()`` is off), each first pass is reprojected along the
    trajectory and refined (drivewm.multiview.reproject), its first frame blended where the cameras
    overlap before (``reprojection.blend``, drivewm.multiview.blend; not with ``condition_clip``);
    with ``prompt_template`` (the default) each prompt is rewritten into the training captions'
    template (:func:`template_view_captions`), without it sampled as given (:func:`view_captions`);
    with ``stitch`` (None: :data:`DEFAULT_STITCH`; never with ``condition_clip``) every decoded frame
    is blended where the cameras overlap (drivewm.multiview.blend.stitch_views)."""
    model = MultiView.from_pretrained(model_dir).to(options.device)
    reprojection = (reprojection or Reprojection(None)).resolved(bool(model.latent.tokenizer))
    warn_if_preview(model_dir, model.latent.tokenizer)
    tokenizer = reprojection_tokenizer(model, reprojection)
    mv = model.cfg.multiview
    rig = load_rig(rig_spec) if rig_spec else None
    cond, speed = None, mv.speed_mps
    if condition_clip is not None:
        cond, rig, clip_speed = condition_latents(model, Path(condition_clip), rig)
        speed = clip_speed if np.isfinite(clip_speed) else speed
    rig = rig or model.training_rig
    stitch = DEFAULT_STITCH if stitch is None else stitch
    if condition_clip is not None:  # the first frames are the clip's own: they agree already
        reprojection, stitch = dataclasses.replace(reprojection, blend=False), False
    waypoints = resolve_trajectory(trajectory or "straight", mv.trajectory_waypoints, mv.trajectory_dt_s, speed)
    samples = []
    jobs = [(p, options.seed + i) for i, p in enumerate(p for p in options.prompts for _ in range(options.num_samples))]
    sampling = {
        "guidance": options.guidance,
        "sampler": options.sampler,
        "trajectory_guidance": trajectory_guidance,
        "guidance_interval": options.guidance_interval,
    }
    for prompt, seed in tqdm(jobs, desc="generate"):
        if prompt_template:
            caps = template_view_captions(prompt, rig, waypoints, mv.trajectory_dt_s)
        else:
            caps = view_captions(prompt, rig)
        z = model.sample_latents(rig, [caps], waypoints[None], [seed], options.steps, cond_latents=cond, **sampling)
        if tokenizer is None:
            videos = decode_latents(z[0], model.latent.tokenizer, model.device)  # (V, T, H, W, 3)
        else:  # the tokenizer reprojection already loaded decodes the first pass too
            videos = decode_views(tokenizer, z[0], model.device)
            if reprojection.blend:
                videos = videos.copy()
                videos[:, 0] = blend_overlaps(videos[:, 0], rig, mv.warp_ground_m, reprojection.walls_m)
            z = refine_reprojected(model, tokenizer, rig, caps, waypoints, seed, videos, reprojection, sampling)
            videos = decode_views(tokenizer, z, model.device)
        if stitch:
            videos = stitch_views(videos, rig, mv.warp_ground_m, reprojection.walls_m)
        extra = {
            "model": str(Path(model_dir).resolve()),
            "prompt": prompt,
            "seed": seed,
            **options.record(),
            "trajectory_guidance": trajectory_guidance,
            "trajectory": trajectory or "straight",
            "speed_mps": float(speed),
            "condition_clip": str(condition_clip or ""),
            "prompt_template": prompt_template,
            **reprojection.record(),
            **({"stitched": True} if stitch else {}),
        }
        samples.append(GeneratedSample(videos, rig, prompt, caps, waypoints, mv.trajectory_dt_s, extra))
    return write_samples(out_dir, samples, model.latent.fps)


def reprojection_tokenizer(model: MultiView, reprojection: Reprojection) -> Tokenizer | None:
    """The tokenizer that reprojection encodes the warped clips with (None when it is off)."""
    if not reprojection.sigma:
        return None
    if not model.latent.tokenizer:
        raise DrivewmError("--reproject needs the model's tokenizer (none recorded in the model folder)")
    return Tokenizer.from_pretrained(model.latent.tokenizer).to(model.device)


def generate_command(args: argparse.Namespace) -> int:
    """``drivewm generate`` for a multi-view model folder (called by drivewm.diffusion.commands)."""
    from drivewm.diffusion.commands import generate_options

    for flag, on in (("--reproject-blend", args.reproject_blend), ("--stitch", args.stitch)):
        if on and args.condition_clip is not None:
            raise DrivewmError(
                f"{args.condition_clip}: {flag} blends generated frames; a --condition-clip's frames are the "
                f"clip's own and are never blended (--no-{flag[2:]}, or leave it out)"
            )
    options = generate_options(args)
    # sigma None: generate's default
    reprojection = Reprojection(
        args.reproject, args.reproject_steps, args.reproject_walls, args.reproject_reshade, args.reproject_blend
    )
    files = generate_multiview(
        args.model,
        options,
        args.rig,
        args.trajectory,
        args.condition_clip,
        args.out,
        args.trajectory_guidance,
        reprojection,
        args.prompt_template is not False,
        args.stitch,
    )
    print(f"wrote {len(files)} files to {args.out}")
    return 0
