"""The benchmark end to end: inputs (shards, mp4 folder, grid video), CLI outputs, documented failures."""

import dataclasses
import json
import math

import numpy as np
import pytest

from drivewm.cli import main
from drivewm.clips import ShardWriter
from drivewm.clips.video import encode_mp4
from drivewm.config import load_yaml, to_dict
from drivewm.errors import DrivewmError
from drivewm.eval.config import EVAL_RECIPES, EvalConfig
from drivewm.eval.inputs import EvalItem
from drivewm.eval.suite import aggregate, evaluate, evaluate_item, run_items
from drivewm.geometry import load_rig


@pytest.fixture(scope="module")
def shard_dir(tmp_path_factory, synth_clip6):
    out = tmp_path_factory.mktemp("shards")
    second = dataclasses.replace(synth_clip6, meta=dataclasses.replace(synth_clip6.meta, key="corridor2"))
    with ShardWriter(out, "synth") as w:
        w.write(synth_clip6)
        w.write(second)
    return out


def test_grey_clip_is_nan_with_status_not_a_crash_or_zero():
    rig = load_rig("front3")
    grey = {c: np.full((9, rig.cameras[0].height, rig.cameras[0].width, 3), 128, np.uint8) for c in rig.names}
    poses = np.repeat(np.eye(4)[None], 9, axis=0)
    poses[:, 0, 3] = np.arange(9.0)
    item = EvalItem("grey", rig, 10.0, poses)
    item.videos = lambda: grey  # the decoded frames of a flat grey video
    m = evaluate_item(item, EvalConfig(metrics=["tse", "cse", "pose", "traj"])).metrics
    # An ego that drives 8 m through frames without motion evidence fails guard_motion, which voids
    # the clip's headline figures: NaN in the clip, pass rates 0, failures in the aggregates.
    assert m["guard_motion"] is False and m["voided_by"] == ["guard_motion"] and m["motion_fraction"] == 0.0
    assert math.isnan(m["tse"]) and m["status"]["tse"] == {"too_few_matches": 8 * 3}
    assert math.isnan(m["cse"]) and set(m["status"]["cse"]) == {"too_few_matches"}
    assert m["pose_success"] == 0.0 and m["registered_fraction"] == 0.0
    assert m["pose_auc"] == 0.0 and math.isnan(m["pose_error_m"])  # nothing registered: every image counts 0
    assert math.isnan(m["ate"]) and m["status"]["traj"] == "not_registered"
    from drivewm.eval.suite import ClipResult

    agg = aggregate([ClipResult("grey", m, {})])
    assert math.isnan(agg["ate"]) and agg["nan_clips"]["ate"] == 1 and agg["pose_success"] == 0.0
    assert agg["tse"] == 4.0 and agg["tse_counted"] == 4.0 and agg["cse"] == 4.0  # voided: counted as failed
    assert agg["voided_clips"]["tse"] == 1 and agg["nan_clips"]["tse"] == 0


def test_path_ratio_is_aggregated_as_a_median_so_one_exploded_path_does_not_carry_it():
    from drivewm.eval.suite import ClipResult

    ratios = [1.0, 0.9, 5010.0, math.nan]  # on the path, on it, exploded, not registered
    agg = aggregate([ClipResult(str(i), {"path_ratio": r}, {}) for i, r in enumerate(ratios)])
    assert agg["path_ratio_median"] == 1.0 and agg["nan_clips"]["path_ratio_median"] == 1
    assert "path_ratio" not in agg  # no mean: 1,670 here
    assert "path_ratio_median" not in aggregate([ClipResult("a", {"tse": 1.0}, {})])  # no clip has one


@pytest.mark.slow
def test_cli_on_shards_writes_json_table_plots_and_recording(shard_dir, tmp_path, capsys):
    out = tmp_path / "eval"
    rc = main(
        [
            "eval",
            str(shard_dir),
            "--out",
            str(out),
            "--metrics",
            "tse,cse",
            "--workers",
            "2",
            "--reference",
            "cosmos_paper",
        ]
    )
    assert rc == 0
    metrics = json.loads((out / "metrics.json").read_text())
    # stdout's summary is strict JSON (no NaN) and equals metrics.json's top level.
    stdout = capsys.readouterr().out
    rest = stdout.partition("\n")[2]  # after the resolved config's line
    summary = json.loads(rest[: rest.rindex("}") + 1], parse_constant=lambda c: pytest.fail(f"{c} in stdout"))
    assert summary == {k: v for k, v in metrics.items() if k not in ("clips", "config")}
    assert metrics["num_clips"] == 2 and set(metrics["clips"]) == {"corridor", "corridor2"}
    assert 0 < metrics["tse"] < 0.3 and 0 < metrics["cse"] < 0.5
    # Same clip twice, scored in two processes: identical numbers.
    assert metrics["clips"]["corridor"]["cse"] == metrics["clips"]["corridor2"]["cse"]
    table = (out / "metrics.md").read_text()
    assert "| tse |" in table and "0.690" in table  # the Cosmos paper's real-video TSE sits beside ours
    assert (out / "error_distributions.png").stat().st_size > 10_000
    assert (out / "eval.rrd").stat().st_size > 10_000


@pytest.mark.slow
def test_mp4_folder_and_grid_inputs_match_the_shard(shard_dir, synth_clip6, tmp_path):
    cfg = EvalConfig(metrics=["cse"])
    ref = evaluate(shard_dir, cfg=cfg, progress=False)["clips"]["corridor"]
    folder = tmp_path / "mp4s"
    folder.mkdir()
    for cam, data in synth_clip6.mp4.items():
        (folder / f"{cam}.mp4").write_bytes(data)
    by_folder = evaluate(folder, rig="nuscenes6", cfg=cfg, progress=False)["clips"]["mp4s"]
    assert by_folder["cse"] == pytest.approx(ref["cse"], abs=1e-9)
    assert by_folder["cse_calibrated"] == pytest.approx(ref["cse_calibrated"], abs=1e-9)

    order = ["CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT", "CAM_BACK_LEFT", "CAM_BACK", "CAM_BACK_RIGHT"]
    v = synth_clip6.videos()
    idx = [synth_clip6.meta.cameras.index(c) for c in order]
    grid = np.concatenate(
        [np.concatenate([v[i] for i in idx[:3]], axis=2), np.concatenate([v[i] for i in idx[3:]], axis=2)], axis=1
    )
    (tmp_path / "grid.mp4").write_bytes(encode_mp4(grid, 10.0))
    by_grid = evaluate(tmp_path / "grid.mp4", rig="nuscenes6", grid="2x3", cameras=order, cfg=cfg, progress=False)[
        "clips"
    ]["grid"]
    print("CSE shard / folder / grid:", ref["cse"], by_folder["cse"], by_grid["cse"])
    assert by_grid["cse"] == pytest.approx(ref["cse"], abs=0.1)  # re-encoded once more
    assert by_grid["cse_calibrated"] < 0.6


def test_bad_inputs_give_one_line_errors(tmp_path, capsys):
    assert main(["eval", str(tmp_path / "missing"), "--out", str(tmp_path / "o")]) == 2
    assert "no such file or folder" in capsys.readouterr().err
    (tmp_path / "x.mp4").write_bytes(b"not a video")
    assert (
        main(["eval", str(tmp_path / "x.mp4"), "--rig", "nuscenes6", "--grid", "2x2", "--out", str(tmp_path / "o")])
        == 2
    )
    assert "4 cells but 6 camera names" in capsys.readouterr().err
    assert main(["eval", str(tmp_path / "x.mp4"), "--rig", "front1", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "x.mp4" in err and err.count("\n") == 1


def test_default_suite_yaml_pins_the_config_defaults():
    assert EVAL_RECIPES.recipe_names() == ["default", "quick"]
    assert to_dict(EVAL_RECIPES.resolve(recipe="default")) == to_dict(EvalConfig())
    written = load_yaml(EVAL_RECIPES.recipe_path("default"))["config"]
    assert set(written) == set(to_dict(EvalConfig()))
    assert all(set(v) == set(to_dict(EvalConfig())[k]) for k, v in written.items() if isinstance(v, dict))
    assert EVAL_RECIPES.resolve(recipe="quick", overrides=["match.ratio=0.75"]).match.ratio == 0.75


@pytest.mark.slow
def test_corrupt_shard_is_reported_and_the_rest_scored(shard_dir, tmp_path):
    import shutil

    folder = tmp_path / "mixed"
    shutil.copytree(shard_dir, folder)
    good = next(folder.glob("*.tar"))
    (folder / "broken-000000.tar").write_bytes(good.read_bytes()[:5000])  # truncated mid-member
    metrics = evaluate(folder, cfg=EvalConfig(metrics=["cse"]), progress=False)
    assert metrics["num_clips"] == 3 and metrics["num_failed_clips"] == 1
    assert "broken-000000.tar" in metrics["clips"]["broken-000000"]["error"]
    assert metrics["clips"]["corridor"]["cse"] < 0.5


def test_cli_summary_is_strict_json_with_null_for_nan(tmp_path, capsys):
    """A flat grey video has no trajectory (ATE NaN in Python): stdout says null, as metrics.json does."""
    folder = tmp_path / "grey"
    folder.mkdir()
    (folder / "CAM_FRONT.mp4").write_bytes(encode_mp4(np.full((5, 192, 320, 3), 128, np.uint8), 10.0))
    out = tmp_path / "eval"
    rc = main(
        ["eval", str(folder), "--rig", "front1", "--metrics", "tse,pose,traj", "--no-pictures", "--out", str(out)]
    )
    assert rc == 0
    stdout = capsys.readouterr().out
    assert "NaN" not in stdout
    resolved, _, rest = stdout.partition("\n")  # the resolved config's line comes first
    assert json.loads(resolved)["metrics"] == ["tse", "pose", "traj"]
    summary = json.loads(rest[: rest.rindex("}") + 1])
    assert summary["ate"] is None and summary["nan_clips"]["ate"] == 1
    # no frame pair shows motion: guard_motion voids the clip, whose TSE counts as failed, not as null
    assert summary["tse_counted"] == 4.0 and summary["voided_clips"]["tse_counted"] == 1
    metrics = json.loads((out / "metrics.json").read_text())
    assert summary == {k: v for k, v in metrics.items() if k not in ("clips", "config")}


def test_max_clips_spreads_the_subset_over_the_input():
    from drivewm.clips.shards import spread

    items = list(range(10))
    assert spread(items, 3) == [0, 3, 6] and spread(items, 5) == [0, 2, 4, 6, 8]
    assert spread(items, None) == items and spread(items, 12) == items
    with pytest.raises(DrivewmError, match="max_clips"):
        spread(items, 0)


def test_a_folder_of_shard_folders_is_scored_with_folder_prefixed_keys(shard_dir, tmp_path):
    """`drivewm eval RUN/generated` (one shard folder per prompt, equal sample keys in each): every
    clip of every folder, none replacing another; a folder without shards is not an input."""
    import shutil

    from drivewm.eval.inputs import load_items

    for name in ("snow_left", "fog_right"):
        shutil.copytree(shard_dir, tmp_path / "generated" / name)
    (tmp_path / "generated" / "notes").mkdir()
    keys = [i.key for i in load_items(tmp_path / "generated")]
    inner = sorted(i.key for i in load_items(shard_dir))
    assert keys == [f"fog_right/{k}" for k in inner] + [f"snow_left/{k}" for k in inner]


@pytest.mark.slow
def test_one_clip_on_two_threads_gives_the_same_figures(synth_item):
    """Threads spread one clip's features, matches and F fits (issue 14's speed goal on 2 cores);
    every figure must be exactly what one thread gives."""
    cfg = EvalConfig(metrics=["tse", "cse", "pose", "traj"])
    one, two = (evaluate_item(synth_item, cfg, threads).metrics for threads in (1, 2))
    for m in (one, two):
        m.pop("seconds")
    assert one["registered_fraction"] == 1.0 and one["tse_counted_fraction"] > 0.5  # a clip worth comparing
    assert json.dumps(one, sort_keys=True, default=str) == json.dumps(two, sort_keys=True, default=str)


def test_clip_threads_fill_the_cores_without_oversubscribing():
    from drivewm.eval.suite import clip_threads

    assert clip_threads(workers=1, clips=6, cores=2) == 2  # one clip at a time: both cores
    assert clip_threads(workers=2, clips=6, cores=2) == 1  # two clips at a time: one core each
    assert clip_threads(workers=4, clips=1, cores=8) == 8  # more workers than clips: the clip gets all
    assert clip_threads(workers=3, clips=9, cores=2) == 1
    with pytest.raises(DrivewmError, match="threads must be >= 1"):
        run_items([], EvalConfig(), threads=0)


def test_matcher_threads_run_in_parallel_and_keep_order():
    import threading
    import time

    from drivewm.eval.config import MatchConfig
    from drivewm.eval.matching import FrameMatcher

    def work(x):
        time.sleep(0.01)  # long enough that one thread cannot take every item
        return x, threading.get_ident()

    out = FrameMatcher(MatchConfig(), threads=2).map(work, range(20))
    assert [x for x, _ in out] == list(range(20)) and len({t for _, t in out}) == 2
    with pytest.raises(DrivewmError, match="threads"):
        FrameMatcher(MatchConfig(), threads=0)


def test_a_pose_stage_failing_beside_tse_is_the_clips_error_not_a_hang(synth_item, monkeypatch):
    """With threads, structure from motion runs beside TSE and CSE, which wait for its database: a
    failure before the database exists must end the clip with its error, not leave TSE waiting."""
    import drivewm.eval.suite as suite

    def broken(*args, **kwargs):
        raise DrivewmError("sfm: no database today")

    monkeypatch.setattr(suite, "run_sfm", broken)
    m = evaluate_item(synth_item, EvalConfig(metrics=["tse", "pose"]), threads=2).metrics
    assert m == {"error": "sfm: no database today"}


def test_a_clip_without_ego_poses_has_no_pose_or_trajectory_error(dashcam_clips):
    """The real dashcam through import-video stores identity placeholder poses (ego motion unknown):
    they are no reference. Before, the drive read as standing still: ATE 0.000 m, rotation error 156 deg."""
    from drivewm.eval.inputs import items_from_clips

    items = items_from_clips(dashcam_clips, None)
    assert len(items) == 5 and all(i.T_world_from_ego is None for i in items)
    m = evaluate_item(items[0], EvalConfig(metrics=["tse", "pose", "traj"])).metrics
    assert m["pose_success"] == 1.0  # the frames register: a real forward drive
    for key in ("ate", "rpe_trans", "rpe_rot", "pose_error_m", "pose_error_deg", "tse_calibrated"):
        assert math.isnan(m.get(key, math.nan)), (key, m[key])
    assert m["status"]["traj"] == "no_reference" and abs(m["yaw_change_deg"]) < 10  # a straight highway
