from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from robot_hoi.errors import UserError
from robot_hoi.utils.config import apply_overrides, load_dataclass, load_yaml_dataclass


@dataclass
class Inner:
    lr: float = 1e-3
    sizes: list[int] = field(default_factory=lambda: [64, 64])
    clip: float | None = None


@dataclass
class Outer:
    name: str
    seed: int = 0
    inner: Inner = field(default_factory=Inner)


def test_nested_load_with_defaults_and_int_to_float():
    cfg = load_dataclass(Outer, {"name": "x", "inner": {"lr": 1, "clip": 0.5}})
    assert cfg.inner.lr == 1.0 and isinstance(cfg.inner.lr, float)
    assert cfg.inner.sizes == [64, 64] and cfg.inner.clip == 0.5 and cfg.seed == 0


@pytest.mark.parametrize(
    "data, message",
    [
        ({"name": "x", "inner": {"lrr": 1.0}}, "inner.lrr"),
        ({"name": "x", "seed": 1.5}, "seed"),
        ({"name": "x", "seed": True}, "seed"),
        ({"name": "x", "inner": {"sizes": [1, "a"]}}, "inner.sizes[1]"),
        ({"seed": 1}, "name"),
    ],
)
def test_rejects_bad_input_naming_the_key(data, message):
    with pytest.raises(UserError, match=message.replace("[", r"\[").replace("]", r"\]")):
        load_dataclass(Outer, data, "my.yaml")


def test_overrides_parse_yaml_values_and_reject_unknown_keys():
    cfg = load_dataclass(Outer, {"name": "x"})
    new = apply_overrides(cfg, ["inner.lr=3e-4", "inner.sizes=[8, 8]", "inner.clip=null", "seed=7"])
    assert new.inner.lr == pytest.approx(3e-4) and new.inner.sizes == [8, 8] and new.seed == 7
    assert cfg.seed == 0  # the original is untouched
    with pytest.raises(UserError, match="inner.nope"):
        apply_overrides(cfg, ["inner.nope=1"])
    with pytest.raises(UserError, match="dotted.key=value"):
        apply_overrides(cfg, ["seed"])


def test_yaml_file_errors_name_the_file(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("name: a\nbogus: 1\n")
    with pytest.raises(UserError, match="c.yaml"):
        load_yaml_dataclass(Outer, path)
    path.write_text("name: a\nseed: 3\n")
    assert load_yaml_dataclass(Outer, path, ["seed=4"]).seed == 4
