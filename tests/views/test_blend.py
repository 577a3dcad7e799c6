"""Overlap blending (drivewm.views.blend, the opt-in ``blend`` and ``stitch`` post-steps): generated views
that disagree where their cameras overlap are made to agree there, and nothing else of them moves."""

from __future__ import annotations

import numpy as np
import pytest

from drivewm.cli import main
from drivewm.clips import iter_clips
from drivewm.geometry import load_rig
from drivewm.views.blend import blend_overlaps, feathered_mean, feathering, overlap_disagreement, stitch_views


def first_frames(sim_clip_dir) -> tuple[np.ndarray, object]:
    clip = next(iter_clips(sorted(sim_clip_dir.glob("*.tar"))[0]))
    rig = clip.meta.get_rig()
    return np.stack([clip.video(n)[0] for n in rig.names]), rig


def test_views_that_disagree_where_their_cameras_overlap_agree_once_blended(sim_clip_dir):
    """A simulated drive's first frames, every other view 40 levels brighter (as two generated views
    of one scene can be): where one camera sees what another sees, their colours differ by tens of
    levels; blended they agree within a few (bilinear sampling and the parallax of what stands
    beside the road), and the shift itself is gone from the overlaps only. Measured on the 320x192
    test clip: 79 levels apart, blended 1.4, the true frames themselves 14 (their roadside's
    parallax); 40 % of the pixels moved."""
    frames, rig = first_frames(sim_clip_dir)
    shift = np.where(np.arange(len(rig.names)) % 2 == 0, 40, -40)[:, None, None, None]
    disagreeing = (frames.astype(int) + shift).clip(0, 255).astype(np.uint8)
    before = overlap_disagreement(disagreeing, rig)
    blended = blend_overlaps(disagreeing, rig)
    after = overlap_disagreement(blended, rig)
    assert before > 40 and after < 0.15 * before, (before, after)
    assert after <= overlap_disagreement(frames, rig)  # agree better than the true frames' parallax lets them
    moved = np.abs(blended.astype(int) - disagreeing).max(axis=-1) > 2
    assert 0.05 < moved.mean() < 0.6  # the overlaps, not the whole image
    front = rig.names.index("CAM_FRONT")
    centre = disagreeing.shape[2] // 2
    assert np.array_equal(blended[front, :, centre], disagreeing[front, :, centre])  # only its own camera sees it


@pytest.mark.slow
def test_stitching_makes_every_frame_agree_and_mixes_no_frame_into_another(sim_clip_dir):
    """A simulated drive, each view brightened or darkened by a shift that changes from frame to
    frame (as views refined each on its own can be): stitched, every frame's overlaps agree within a
    fraction of what they disagreed, and each frame is its own frame blended, no other's."""
    clip = next(iter_clips(sorted(sim_clip_dir.glob("*.tar"))[0]))
    rig = clip.meta.get_rig()
    videos = np.stack([clip.video(n)[:6] for n in rig.names]).astype(int)
    sign = np.where(np.arange(len(rig.names)) % 2 == 0, 1, -1)[:, None]
    shift = sign * np.array([40, -30, 20, 45, -40, 10])[None, :]  # (V, T): differs per view and per frame
    disagreeing = (videos + shift[..., None, None, None]).clip(0, 255).astype(np.uint8)
    stitched = stitch_views(disagreeing, rig)
    for t in range(disagreeing.shape[1]):
        before, after = overlap_disagreement(disagreeing[:, t], rig), overlap_disagreement(stitched[:, t], rig)
        assert before > 15 and after < 0.2 * before, (t, before, after)
        assert np.array_equal(stitched[:, t], blend_overlaps(disagreeing[:, t], rig))
    with pytest.raises(ValueError, match="5 views for a rig of 6"):
        stitch_views(disagreeing[:5], rig)


def test_blending_keeps_views_that_agree_everywhere_and_refuses_a_mismatched_rig():
    rig = load_rig("nuscenes6").scaled(160, 96)
    uniform = np.full((6, 96, 160, 3), (90, 100, 110), np.uint8)
    assert np.array_equal(blend_overlaps(uniform, rig), uniform)
    assert overlap_disagreement(uniform, rig) < 1e-6
    with pytest.raises(ValueError, match="5 views for a rig of 6"):
        blend_overlaps(uniform[:5], rig)
    plan, values = feathering(rig, (96, 160)), uniform[:, None].astype(np.float32)
    with pytest.raises(ValueError, match="a guide needs a tolerance > 0, got None"):
        feathered_mean(values, plan, guide=values)  # the tolerance is the guide's scale: no default fits all
    assert np.allclose(feathered_mean(values, plan, guide=values, tolerance=30.0), values)


@pytest.mark.slow
def test_a_generated_clips_cameras_agree_where_they_overlap_with_the_blend_and_the_stitch(tmp_path):
    """The shipped model, one prompt and seed, reprojected with and without the ``blend`` post-step
    (unstitched): the first frames of the blended sample disagree across the overlaps by a fraction
    of the unblended ones', the refined frames after it too. With ``stitch`` as well, the last frame
    disagrees by a fraction of the unstitched one's. Each clip names the post-steps done to it."""
    got = {}
    for steps in ("reproject,blend", "reproject", "reproject,blend,stitch"):
        out = tmp_path / steps.replace(",", "_")
        argv = ["generate", "--prompt", "a clear day on a suburban road", "--trajectory", "left", "--seed", "5"]
        argv += ["--steps", "3", "--guidance", "1", "--device", "cpu", "--set", "reproject.steps=3", "--out", str(out)]
        assert main([*argv, "--set", f"post_processing=[{steps}]"]) == 0
        clip = next(iter_clips(sorted(out.glob("*.tar"))[0]))
        rig = clip.meta.get_rig()
        videos = np.stack([clip.video(n) for n in rig.names])
        got[steps] = [overlap_disagreement(videos[:, t], rig) for t in (0, videos.shape[1] - 1)]
        assert clip.meta.extra["post_processing"] == steps.split(",")
    blended, plain = got["reproject,blend"], got["reproject"]
    assert blended[0] < 0.5 * plain[0] and blended[1] < plain[1], got
    assert got["reproject,blend,stitch"][1] < 0.5 * blended[1], got
