"""The shipped-model recipe: every stage of every profile is a valid drivewm command line."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from drivewm import resources
from drivewm.cli import build_parser, main
from drivewm.errors import DrivewmError
from drivewm.product.worldmodel import benchmark_stages, generate_recipe, load_profile, stage_commands


@pytest.mark.parametrize("profile", ["cpu", "gpu"])
def test_every_stage_parses_and_chains_its_outputs(profile, tmp_path):
    p = load_profile(profile)
    stages = stage_commands(p, tmp_path)
    parser = build_parser()
    for name, argv in stages:
        args = parser.parse_args(argv)  # a typo in a profile fails here, not hours into a run
        assert callable(args.func), name
    names = [n for n, _ in stages]
    assert names.index("tokenizer-train") < names.index("encode-train") < names.index("pretrain-image")
    assert names.index("pretrain-image") < names.index("pretrain-video") < names.index("posttrain")
    argv = dict(stages)
    assert argv["pretrain-video"][argv["pretrain-video"].index("--init") + 1] == str(tmp_path / "text2world_image")
    assert argv["posttrain"][argv["posttrain"].index("--init") + 1] == str(tmp_path / "text2world")
    transfer = argv["transfer-train"]  # paired drives' latents from the run's tokenizer, init its video model
    assert transfer[transfer.index("--init") + 1] == str(tmp_path / "text2world")
    assert transfer[transfer.index("--data") + 1] == argv["encode-paired"][-1] == str(tmp_path / "clips" / "paired")
    assert argv["encode-paired"][argv["encode-paired"].index("--model") + 1] == str(tmp_path / "tokenizer")
    generated = [n for n in names if n.startswith("generate-")]
    assert len(generated) * p.samples_per_benchmark >= 24  # the 24 generated clips at least
    for _, argv in stages:  # packaged recipes, found by name for their stage
        if "--recipe" in argv:
            assert resources.find(f"recipes/{argv[0]}", argv[argv.index("--recipe") + 1], "recipe").is_file()


def test_the_benchmark_of_any_model_is_the_recipes_benchmark_stages(tmp_path):
    """`drivewm worldmodel benchmark` scores a given model (a fleet fine-tune) on the stages the recipe
    scores its own multi-view model with: same prompts, seeds, sampler and eval, another --model."""
    p = load_profile("cpu")
    recipe = [(n, a) for n, a in stage_commands(p, tmp_path) if n.startswith(("generate-", "eval-", "figures"))]
    mine = benchmark_stages(p, "shipped:multiview", tmp_path, tmp_path / "clips" / "heldout")
    assert [n for n, _ in mine] == [n for n, _ in recipe]
    for (_, a), (_, b) in zip(mine, recipe):
        if a[0] == "generate":
            i = a.index("--model")
            assert a[i + 1] == "shipped:multiview" and b[i + 1] == str(tmp_path / "multiview")
            a, b = a[:i] + a[i + 2 :], b[:i] + b[i + 2 :]
        assert a == b
    more = dict(benchmark_stages(p, "m", tmp_path, tmp_path, samples=4))
    assert all(a[a.index("--num-samples") + 1] == "4" for n, a in more.items() if n.startswith("generate-"))
    parser = build_parser()
    assert all(callable(parser.parse_args(argv).func) for _, argv in mine)

    def generated(recipe) -> list:  # each prompt's generate command, parsed, with the generate recipe given
        stages = benchmark_stages(p, "m", tmp_path, tmp_path, recipe=recipe)
        parsed = [parser.parse_args(a) for n, a in stages if n.startswith("generate-")]
        assert len(parsed) == len(p.benchmarks)
        return parsed

    assert all(a.recipe is None and a.overrides == [] for a in generated(None))  # generate's own defaults
    assert generate_recipe(tmp_path, None, []) is None
    written = generate_recipe(tmp_path, "reprojected", ["sampling.trajectory_guidance=4"])
    assert all(a.recipe == str(written) for a in generated(written))
    from drivewm.generate.config import RECIPES

    cfg = RECIPES.resolve(recipe=written)  # the recipe written holds the whole resolved config
    assert cfg.sampling.trajectory_guidance == 4.0 and cfg.post_processing == [
        "reproject",
        "reshade",
        "blend",
        "stitch",
    ]
    assert generate_recipe(tmp_path, "reprojected", ["sampling.trajectory_guidance=4"]) == written  # same: resumes
    assert generate_recipe(tmp_path, None, ["sampling.trajectory_guidance=2"]) != written  # other settings: rerun
    with pytest.raises(DrivewmError, match="post_processing"):
        generate_recipe(tmp_path, None, ["post_processing=[warp]"])  # refused before any stage runs


def test_benchmark_reuses_an_earlier_heldout_eval(tmp_path, monkeypatch):
    """--heldout an earlier benchmark's RUN/eval/heldout/metrics.json: it becomes this run's reference
    as it is, and the held-out clips are not evaluated again; every other stage is the recipe's."""
    import drivewm.product.quickstart

    earlier = {"num_clips": 48, "tse_calibrated": 0.957, "clips": {"a": {"tse_calibrated": 0.9}}}
    (tmp_path / "earlier.json").write_text(json.dumps(earlier))
    ran = []
    monkeypatch.setattr(
        drivewm.product.quickstart, "run_stage", lambda name, argv, run, label, **kw: ran.append((name, argv))
    )
    run = tmp_path / "run"
    argv = ["worldmodel", "benchmark", "--heldout", str(tmp_path / "earlier.json"), "--out", str(run)]
    assert main([*argv, "--set", "post_processing=[stitch]"]) == 0
    assert json.loads((run / "eval" / "heldout" / "metrics.json").read_text()) == earlier
    recipe = generate_recipe(run, None, ["post_processing=[stitch]"])  # the generate settings reach every stage
    full = benchmark_stages(load_profile("cpu"), "shipped:multiview", run, tmp_path / "earlier.json", recipe=recipe)
    assert ran == [(n, a) for n, a in full if n != "eval-heldout"] and len(ran) == len(full) - 1
    reference = dict(ran)["eval-generated"]
    assert reference[reference.index("--reference") + 1] == str(run / "eval" / "heldout" / "metrics.json")


def test_a_rerun_given_the_tokenizer_eval_computes_the_figures_again(tmp_path, monkeypatch):
    """Generation and eval resume; the figures must not, or the tokenizer's PSNR given on a rerun never
    reaches figures.json: the figures stage's marker goes."""
    import drivewm.product.quickstart

    run = tmp_path / "run"
    marker = drivewm.product.quickstart.stage_marker(run, "figures")
    marker.parent.mkdir(parents=True)
    marker.write_text(json.dumps({"argv": ["worldmodel", "figures", str(run)], "seconds": 0.1}))
    (tmp_path / "earlier.json").write_text(json.dumps({"num_clips": 1, "clips": {"a": {}}}))
    (tmp_path / "tok.json").write_text(json.dumps({"psnr": 29.93, "clips": {}}))
    monkeypatch.setattr(drivewm.product.quickstart, "run_stage", lambda name, argv, run, label, **kw: None)
    argv = ["worldmodel", "benchmark", "--heldout", str(tmp_path / "earlier.json"), "--out", str(run)]
    assert main([*argv]) == 0
    assert marker.is_file()  # no tokenizer eval: the figures stay as they were
    assert main([*argv, "--tokenizer-eval", str(tmp_path / "tok.json")]) == 0
    assert not marker.exists()
    assert json.loads((run / "eval" / "tokenizer" / "metrics.json").read_text())["psnr"] == 29.93


@pytest.mark.parametrize(
    "args, message",
    [
        (["--model", "{tmp}/MISSING"], "--model {tmp}/MISSING is not a model folder (no config.json)"),
        (["--heldout", "{tmp}/nowhere"], "--heldout {tmp}/nowhere is not a clip folder"),
        (["--tokenizer-eval", "{tmp}/heldout/bad.json"], "bad.json is not a `tokenizer eval` metrics.json"),
        (["--heldout", "{tmp}/heldout/bad.json"], "bad.json is not a `drivewm eval` metrics.json"),
        (["--samples-per-prompt", "0"], "must be in [1, 64], got 0"),
        (["--set", "sampling.trajectory_guidance=nan"], "sampling.trajectory_guidance: expected a number"),
        (["--set", "post_processing=[warp]"], "post_processing must be a list of"),
        (["--recipe", "nowhere"], "nowhere"),
    ],
)
def test_benchmark_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys, args, message):
    (tmp_path / "heldout").mkdir()
    (tmp_path / "heldout" / "bad.json").write_text('{"ssim": 0.7}')
    argv = ["worldmodel", "benchmark", "--heldout", str(tmp_path / "heldout"), "--out", str(tmp_path / "run")]
    assert main([*argv, *[a.format(tmp=tmp_path) for a in args]]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("error: ") and message.format(tmp=tmp_path) in err, err
    assert not (tmp_path / "run").exists()


def _clip(weather, time_of_day, cond_yaw, yaw, tfe=1.0, match_w=1.0, match_t=1.0):
    prompted = {"weather": weather, "time_of_day": time_of_day}
    adherence = {"prompted": prompted, "weather_match": match_w, "time_of_day_match": match_t}
    return {"adherence": adherence, "conditioned_yaw_change_deg": cond_yaw, "yaw_change_deg": yaw, "tfe": tfe}


def _write_run(run, clips, gen_top, real_top, psnr):
    from drivewm.atomic import write_json

    write_json(run / "eval" / "generated" / "metrics.json", {**gen_top, "clips": dict(enumerate(clips))})
    write_json(run / "eval" / "heldout" / "metrics.json", {**real_top, "num_clips": 20})
    write_json(run / "eval" / "tokenizer" / "metrics.json", {"psnr": psnr})


GOOD_CLIPS = [
    _clip("snow", "day", 20.0, 14.0),
    _clip("fog", "day", -25.0, -9.0),
    _clip("rain", "dusk", 0.0, 1.0),
    _clip("clear", "night", 0.0, -0.5),
    _clip("clear", "day", 18.0, 3.0),
]
REAL = {"tfe": 1.0, "tse_calibrated": 0.5, "cse_calibrated": 1.0, "tse_calibrated_counted_fraction": 0.9,
        "cse_calibrated_counted_fraction": 0.5}  # fmt: skip
GOOD = {"pose_success": 0.8, "pose_success_path": 0.7, "tse_calibrated": 0.7, "cse_calibrated": 1.5,
        "tse_calibrated_matches": 40, "cse_calibrated_matches": 30, "tse_calibrated_counted_fraction": 0.95,
        "cse_calibrated_counted_fraction": 0.5}  # fmt: skip


def test_figures_hold_on_a_run_that_meets_them(tmp_path):
    from drivewm.product.figures import figures

    _write_run(tmp_path, GOOD_CLIPS, GOOD, REAL, 33.0)
    figs = figures(tmp_path)
    failing = [k for k, f in figs.items() if isinstance(f, dict) and not f["holds"]]
    assert failing == [] and figs["generated_clips"] == 5
    assert figs["turn_sign_rate"]["value"] == 1.0 and figs["turn_sign_rate"]["clips"] == 3
    assert figs["turn_sign_rate"]["unreadable"] == 0 and figs["straight_abs_yaw_deg"]["unreadable"] == 0
    assert figs["adherence_night"]["clips"] == 1


@pytest.mark.parametrize(
    "change, broken",
    [
        (lambda c, g, r: c[0].update(yaw_change_deg=-3.0), "turn_sign_rate"),  # a left sample turning right
        (lambda c, g, r: c[2].update(yaw_change_deg=40.0), "straight_abs_yaw_deg"),  # straight turns most
        (lambda c, g, r: c[0].pop("yaw_change_deg"), "turn_sign_rate"),  # an unreadable turn fails, not left out
        (lambda c, g, r: c[2].pop("yaw_change_deg"), "straight_abs_yaw_deg"),  # a blank straight sample fails
        (lambda c, g, r: c[0]["adherence"].update(weather_match=0.0), "adherence_snow"),
        (lambda c, g, r: c[3]["adherence"].update(time_of_day_match=0.0), "adherence_night"),
        (lambda c, g, r: [x.update(tfe=3.5) for x in c], "tfe_ratio_to_real"),
        (lambda c, g, r: g.update(pose_success=0.4), "pose_success"),
        # every frame registers, but the reconstructions stand still: the 320x192 samples' case
        (lambda c, g, r: g.update(pose_success_path=0.0), "pose_success_path"),
        (lambda c, g, r: g.update(cse_calibrated=2.5), "cse_calibrated_ratio_to_real"),
        (
            lambda c, g, r: g.update(tse_calibrated_counted_fraction=0.5),
            "tse_calibrated_ratio_to_real",
        ),  # blur wins on few matches: fewer of its pairs count than the real clips'
        (
            lambda c, g, r: (
                g.update(cse_calibrated=4.0, cse_calibrated_counted_fraction=0.0)
                or r.update(cse_calibrated=2.36, cse_calibrated_counted_fraction=0.49)
            ),
            "cse_calibrated_ratio_to_real",
        ),  # the shipped models' case: no generated pair counts, both values mostly the 4 px penalty
        (lambda c, g, r: g.pop("pose_success"), "pose_success"),  # not measured never holds
    ],
)
def test_each_figure_can_fail(tmp_path, change, broken):
    import copy

    from drivewm.product.figures import figures

    clips, gen, real = copy.deepcopy(GOOD_CLIPS), dict(GOOD), dict(REAL)
    change(clips, gen, real)
    _write_run(tmp_path, clips, gen, real, 33.0)
    figs = figures(tmp_path)
    assert [k for k, f in figs.items() if isinstance(f, dict) and not f["holds"]] == [broken]


def test_the_cse_figure_carries_the_overlap_disagreement_that_shows_a_stitched_cse(tmp_path):
    """Stitched views win CSE by construction (docs/eval-protocol.md): the CSE figure reports the eval's
    ``overlap_disagreement`` beside it, generated and held-out, in figures.json and in the table; an
    eval without it (an older metrics.json) leaves the figure as it was."""
    from drivewm.product.figures import figures, figures_markdown

    _write_run(
        tmp_path, GOOD_CLIPS, {**GOOD, "overlap_disagreement": 2.08}, {**REAL, "overlap_disagreement": 8.23}, 33.0
    )
    figs = figures(tmp_path)
    cse = figs["cse_calibrated_ratio_to_real"]
    assert (cse["overlap_disagreement"], cse["real_overlap_disagreement"]) == (2.08, 8.23) and cse["holds"]
    assert "| cse_calibrated_ratio_to_real | 1.5 (overlap disagreement 2.1 levels, held-out 8.2) |" in figures_markdown(
        figs
    )
    _write_run(tmp_path, GOOD_CLIPS, GOOD, REAL, 33.0)
    assert "overlap_disagreement" not in figures(tmp_path)["cse_calibrated_ratio_to_real"]


def test_tokenizer_psnr_below_goal_does_not_hold(tmp_path):
    from drivewm.product.figures import figures, figures_markdown

    _write_run(tmp_path, GOOD_CLIPS, GOOD, REAL, 28.4)
    figs = figures(tmp_path)
    assert figs["tokenizer_psnr_db"] == {"value": 28.4, "goal": ">= 32", "holds": False}
    assert "| tokenizer_psnr_db | 28.4 | >= 32 | no |" in figures_markdown(figs)


def test_an_unreadable_turn_counts_against_the_turn_sign_and_the_table_says_so(tmp_path):
    import copy

    from drivewm.product.figures import figures, figures_markdown

    clips = copy.deepcopy(GOOD_CLIPS)
    clips[1].pop("yaw_change_deg")  # the right turn: no motion read where the trajectory moves
    _write_run(tmp_path, clips, GOOD, REAL, 33.0)
    figs = figures(tmp_path)
    sign = figs["turn_sign_rate"]
    assert (sign["value"], sign["clips"], sign["unreadable"]) == (round(2 / 3, 4), 3, 1)
    assert "| turn_sign_rate | 0.6667 (1 unreadable) | >= 0.9 | no |" in figures_markdown(figs)


def test_a_run_moved_to_another_folder_resumes_where_it_stopped(tmp_path, monkeypatch):
    """A run copied from a GPU machine, moved, or named from another directory keeps its finished
    stages: a marker's command counts with the run's old path in place of the new one. Any other
    change reruns the stage (that the moved outputs still work: tests/train/test_relocation.py)."""
    import drivewm.product.quickstart
    from drivewm.product.quickstart import run_stage

    ran = []
    monkeypatch.setattr(drivewm.product.quickstart, "main", lambda argv: ran.append(argv) or 0)

    def stage(run: Path, model: str = "m") -> list:
        argv = ["generate", "--model", model, "--out", str(run / "generated" / "a"), "--ref", str(run)]
        ran.clear()
        run_stage("generate-a", argv, run, "worldmodel")
        return ran[:]

    old = tmp_path / "gpu" / "run"
    assert stage(old) and not stage(old)  # ran once, then resumed
    new = tmp_path / "moved"
    shutil.move(old, new)
    assert not stage(new)  # the same command with the run's new path: done before
    from drivewm.product.model_card import _stages

    assert _stages(new)[-1] == "| generate-a | 0 | `drivewm generate --model m --out RUN/generated/a --ref RUN` |"
    assert stage(new, model="other")  # another model: runs
    assert not stage(new, model="other")
    shutil.move(new, tmp_path / "again")
    assert not stage(tmp_path / "again", model="other")  # moved twice
    earlier = drivewm.product.quickstart.stage_marker(tmp_path / "again", "generate-a")
    marker = json.loads(earlier.read_text())
    earlier.write_text(json.dumps({"argv": marker["argv"], "seconds": 1.0}))  # written before the run was recorded
    shutil.move(tmp_path / "again", tmp_path / "last")
    assert stage(tmp_path / "last", model="other")  # its old path unknown: runs again
