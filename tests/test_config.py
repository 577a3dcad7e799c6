import dataclasses

import pytest

from drivewm.config import apply_overrides, from_dict, load_yaml
from drivewm.errors import DrivewmError


@dataclasses.dataclass
class Inner:
    lr: float = 1e-3
    steps: int = 10


@dataclasses.dataclass
class Outer:
    name: str = "run"
    train: Inner = dataclasses.field(default_factory=Inner)
    sizes: list[int] = dataclasses.field(default_factory=lambda: [1, 2])


def test_overrides_reach_nested_fields_with_their_types():
    cfg = apply_overrides(Outer, {"train": {"steps": 3}}, ["train.lr=2e-4", "name=x", "sizes=[3,4]"])
    assert cfg.train.lr == pytest.approx(2e-4) and isinstance(cfg.train.lr, float)
    assert (cfg.train.steps, cfg.name, cfg.sizes) == (3, "x", [3, 4])


@pytest.mark.parametrize(
    "override,message",
    [
        ("train.stpes=3", r"unknown key\(s\) \['stpes'\]"),
        ("train.steps=three", "expected an integer"),
        ("train.steps=true", "expected an integer"),
        ("train.lr=fast", "expected a number"),
        ("novalue", "expected KEY=VALUE"),
    ],
)
def test_bad_overrides_are_clear_errors(override, message):
    with pytest.raises(DrivewmError, match=message):
        apply_overrides(Outer, {}, [override])


def test_yaml_errors_name_the_file(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("a: [1, 2")
    with pytest.raises(DrivewmError, match="bad.yaml: not valid YAML"):
        load_yaml(bad)
    with pytest.raises(DrivewmError, match="config file not found"):
        load_yaml(tmp_path / "missing.yaml")
    assert from_dict(Outer, {}).train.steps == 10


#: 342 bytes that expand to 10^9 strings ("billion laughs"): nine levels, each nine aliases of the one above.
LAUGHS = 'a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n' + "".join(
    f"{n}: &{n} [{','.join([f'*{p}'] * 9)}]\n" for p, n in zip("abcdefgh", "bcdefghi")
)


def test_aliases_that_expand_beyond_the_bound_or_into_themselves_are_refused_at_once(tmp_path, capsys):
    """Issue 70: a 370-byte recipe of nested aliases had kept ``curate --dry-run`` busy past 60 s, and an alias
    inside its own anchor had ended in a RecursionError traceback ~1,000 frames long. Both are one line
    naming the file; aliases that expand to a sane size load as before."""
    from drivewm.cli import main

    for name, text, message in [
        ("laughs.yaml", LAUGHS, "its aliases expand it to more than 100,000 values; write the values out"),
        ("loop.yaml", "config: &loop\n  filters: *loop\n", "an alias refers to a node that contains it (line 1)"),
        ("seq.yaml", "overrides: &o [*o]\n", "an alias refers to a node that contains it (line 1)"),
    ]:
        (tmp_path / name).write_text(text)
        argv = ["curate", "x.mcap", "--out", str(tmp_path / "o"), "--recipe", str(tmp_path / name), "--dry-run"]
        assert main(argv) == 2
        assert capsys.readouterr().err == f"error: {tmp_path / name}: {message}\n"
    (tmp_path / "ok.yaml").write_text("a: &cams [CAM_FRONT, CAM_BACK]\nb: *cams\nc: {x: *cams}\n")
    assert load_yaml(tmp_path / "ok.yaml") == {"a": ["CAM_FRONT", "CAM_BACK"]} | {
        "b": ["CAM_FRONT", "CAM_BACK"],
        "c": {"x": ["CAM_FRONT", "CAM_BACK"]},
    }
    assert len(LAUGHS) < 370
