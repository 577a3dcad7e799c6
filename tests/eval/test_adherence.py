"""Condition statistics and the simulator-calibrated classifier on held-out simulated clips."""

import numpy as np
import pytest

from drivewm.errors import DrivewmError
from drivewm.eval.adherence import FEATURES, adherence, classify_condition, condition_scores


def test_scores_have_every_feature_and_react_physically():
    rng = np.random.default_rng(0)
    frames = rng.integers(40, 220, (4, 64, 96, 3), dtype=np.uint8)
    s = condition_scores(frames)
    assert set(s) == set(FEATURES)
    dark = condition_scores((frames * 0.2).astype(np.uint8))
    assert dark["luma_mean"] < 0.3 * s["luma_mean"]
    static = condition_scores(np.repeat(frames[:1], 4, axis=0))
    assert static["flicker"] == 0.0 and s["flicker"] > 0.05  # independent noise frames flicker
    with pytest.raises(DrivewmError):
        condition_scores(frames.astype(np.float32))


def test_classifier_recognises_held_out_simulated_clips(sim_clip_dir):
    """The fixture's drives (seeds 1-4) were not among the calibration renders (seeds 100-101)."""
    from drivewm.clips import iter_clips

    results = []
    for clip in list(iter_clips(sim_clip_dir))[::3]:  # one clip per drive
        pred = classify_condition(condition_scores(clip.videos()))
        tags = clip.meta.tags
        results.append((tags["weather"], tags["time_of_day"], pred["weather"], pred["time_of_day"]))
        out = adherence(condition_scores(clip.videos()), tags)
        assert out["weather_match"] == float(pred["weather"] == tags["weather"])
    print("(tag weather, tag time, predicted weather, predicted time):", results)
    assert all(t == pt for _, t, _, pt in results)
    assert sum(w == pw for w, _, pw, _ in results) >= len(results) - 1


def test_classifier_recognises_held_out_clips_coded_by_the_shipped_tokenizer(sim_clip_dir):
    """Generated and transferred clips are tokenizer outputs: the fixture's clips resized to the
    shipped models' 160x96 and coded by the shipped tokenizer keep their weather and time of day.
    (Before the coded domain, a coded snow render read as fog: the flakes are what a tokenizer drops.)"""
    from drivewm.clips import iter_clips
    from drivewm.model_folders import shipped_model
    from drivewm.multiview.coding import code_views
    from drivewm.tokenizer import Tokenizer

    tok = Tokenizer.from_pretrained(shipped_model("tokenizer"))
    results = []
    for clip in list(iter_clips(sim_clip_dir))[::3]:  # one clip per drive
        frames = code_views(tok, clip.videos(), (96, 160))
        pred = classify_condition(condition_scores(frames))
        tags = clip.meta.tags
        results.append((tags["weather"], tags["time_of_day"], pred["weather"], pred["time_of_day"]))
    print("(tag weather, tag time, predicted weather, predicted time):", results)
    assert {w for w, *_ in results} >= {"clear", "snow"} and "night" in {t for _, t, *_ in results}
    assert all(w == pw and t == pt for w, t, pw, pt in results)
