"""Property tests (hypothesis): whatever a user types into ``--set`` or writes into a rig, recipe or
scenario YAML, the loaders give a valid config or a one-line DrivewmError, never another exception."""

from __future__ import annotations

import dataclasses
import string
import tempfile
import typing
from pathlib import Path

import numpy as np
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivewm.config import apply_overrides
from drivewm.curate.config import CurateConfig
from drivewm.diffusion.pretrain import PretrainConfig, pretrain_config
from drivewm.errors import DrivewmError
from drivewm.eval.config import EvalConfig
from drivewm.geometry import load_rig
from drivewm.multiview.posttrain import PosttrainConfig
from drivewm.recipe import RecipeBook
from drivewm.sim.config import SimConfig
from drivewm.sim.recipe import load_recipe
from drivewm.tokenizer.config import LossConfig, TokenizerConfig
from drivewm.tokenizer.recipe import TokenizerTrainConfig
from drivewm.train.config import TrainConfig

CONFIGS = (
    PretrainConfig,
    PosttrainConfig,
    CurateConfig,
    EvalConfig,
    SimConfig,
    TrainConfig,
    TokenizerConfig,
    LossConfig,
    TokenizerTrainConfig,
)
SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def field_paths(cls: type, prefix: str = "") -> list[str]:
    """Every dotted field path of a config dataclass, nested ones included."""
    paths = []
    for f in dataclasses.fields(cls):
        tp = typing.get_type_hints(cls)[f.name]
        paths.append(prefix + f.name)
        if dataclasses.is_dataclass(tp):
            paths += field_paths(tp, f"{prefix}{f.name}.")
    return paths


#: YAML-ish value text: numbers at the edges, special floats, broken brackets, tags, nested lists.
SCALARS = st.one_of(
    st.integers(-(2**70), 2**70).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from([".nan", ".inf", "-.inf", "nan", "1e999", "-0", "0x1F", "true", "null", "~", "''", "[]", "{}"]),
    st.sampled_from(["[64,", "{a: 1", "!!python/object:os.system ls", "*alias", "&a [1]", "'x", '"\\x"', "- a"]),
    st.text(alphabet=string.printable, max_size=12),
)
VALUES = st.recursive(
    SCALARS, lambda inner: st.lists(inner, max_size=4).map(lambda v: "[" + ", ".join(v) + "]"), max_leaves=8
)


def _accept(build, *args) -> None:
    """Call ``build``: a config comes back (and re-validates), or a one-line DrivewmError."""
    try:
        cfg = build(*args)
    except DrivewmError as exc:
        assert "\n" not in str(exc), str(exc)
        return
    validate = getattr(cfg, "validate", None)
    if validate is not None:
        validate()


@SETTINGS
@given(data=st.data())
def test_random_overrides_give_a_config_or_a_drivewm_error(data):
    cls = data.draw(st.sampled_from(CONFIGS))
    keys = st.one_of(st.sampled_from(field_paths(cls)), st.text(alphabet="abc._=", max_size=8))
    overrides = data.draw(st.lists(st.tuples(keys, VALUES).map("=".join), min_size=1, max_size=4))
    _accept(apply_overrides, cls, {}, overrides, cls.__name__)


@SETTINGS
@given(overrides=st.lists(st.tuples(st.sampled_from(field_paths(PretrainConfig)), VALUES).map("=".join), max_size=3))
def test_pretrain_recipes_with_random_overrides(overrides):
    _accept(pretrain_config, "debug", overrides)


#: Random YAML documents: mappings, lists and scalars of every type, nested.
YAML_LEAVES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**40), 2**40),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
)
YAML_DOCS = st.recursive(
    YAML_LEAVES,
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=4)),
    max_leaves=20,
)


def _camera_docs() -> st.SearchStrategy:
    """Camera entries near the valid form: each field valid, missing, or replaced by random YAML."""
    number = st.one_of(st.floats(-1e4, 1e4), st.integers(-5, 2000))
    valid = {
        "name": st.sampled_from(["CAM_FRONT", "c1", "../x", "a.b", "", "x" * 200]),
        "width": st.one_of(st.integers(-2, 2000), st.just("abc")),
        "height": st.integers(-2, 2000),
        "K": st.lists(st.lists(number, min_size=2, max_size=4), min_size=2, max_size=4),
        "hfov_deg": number,
        "xyz": st.lists(number, min_size=2, max_size=4),
        "yaw_deg": number,
        "T_ego_from_cam": st.lists(st.lists(number, min_size=4, max_size=4), min_size=4, max_size=4),
        "distortion": st.lists(number, max_size=5),
    }
    field = {k: st.one_of(v, YAML_DOCS) for k, v in valid.items()}
    return st.fixed_dictionaries({}, optional=field)


_FOLDER = tempfile.TemporaryDirectory(prefix="drivewm-prop-")  # removed when the module is collected


def _write(text: str) -> Path:
    path = Path(_FOLDER.name) / "file.yaml"
    path.write_text(text)
    return path


@SETTINGS
@given(doc=st.one_of(st.fixed_dictionaries({"cameras": st.lists(_camera_docs(), max_size=3)}), YAML_DOCS))
def test_random_rig_yaml_gives_a_rig_or_a_drivewm_error(doc):
    try:
        rig = load_rig(_write(yaml.safe_dump(doc)))
    except DrivewmError as exc:
        assert "\n" not in str(exc)
        return
    for cam in rig.cameras:  # what loaded is usable: an invertible K, a rigid pose
        assert np.isfinite(np.linalg.inv(cam.K)).all() and cam.width > 0 and cam.height > 0


@SETTINGS
@given(text=st.text(alphabet=string.printable, max_size=80))
def test_random_text_as_a_rig_file(text):
    try:
        load_rig(_write(text))
    except DrivewmError:
        pass


BOOK = RecipeBook("pretrain", PretrainConfig, {"debug": {"train": {"steps": 3}}}, "debug")


@SETTINGS
@given(
    doc=st.one_of(
        YAML_DOCS,
        st.fixed_dictionaries(
            {},
            optional={
                "preset": st.one_of(st.just("debug"), YAML_DOCS),
                "config": st.one_of(st.fixed_dictionaries({}, optional={"train": YAML_DOCS}), YAML_DOCS),
                "overrides": st.one_of(
                    st.lists(st.tuples(st.sampled_from(field_paths(PretrainConfig)), VALUES).map("=".join), max_size=3),
                    YAML_DOCS,
                ),
            },
        ),
    )
)
def test_random_recipe_yaml_gives_a_config_or_a_drivewm_error(doc):
    _accept(BOOK.resolve, None, _write(yaml.safe_dump(doc)), [])


@SETTINGS
@given(
    doc=st.one_of(
        YAML_DOCS,
        st.fixed_dictionaries(
            {
                "drives": st.lists(
                    st.dictionaries(st.sampled_from(field_paths(SimConfig) + ["count"]), YAML_DOCS), max_size=3
                )
            },
            optional={"common": YAML_DOCS},
        ),
    )
)
def test_random_scenario_recipes_give_configs_or_a_drivewm_error(doc):
    _accept(load_recipe, _write(yaml.safe_dump(doc)))
