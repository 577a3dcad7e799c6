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
