"""The embodiment YAML has two parsers on purpose (deploy/ must not import robot_hoi): robot_hoi.embodiment.config
for training, deploy.embodiment for the robot. Every field they share must read the same from every shipped
file."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import deploy.embodiment as deploy_embodiment
from robot_hoi.embodiment import config as train_embodiment

SHARED = {"name", "control_dt", "actuators", "hands", "link_map"}  # at least these


def plain(value):
    """Dataclasses, tuples and arrays as dicts, lists and floats; a training HandCfg as its channel list."""
    if isinstance(value, train_embodiment.HandCfg):
        return plain(value.channels)
    if dataclasses.is_dataclass(value):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [plain(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, bool | str) or value is None:
        return value
    return float(value)


def shared_fields() -> set[str]:
    ours = {f.name for f in dataclasses.fields(train_embodiment.EmbodimentConfig)}
    theirs = {f.name for f in dataclasses.fields(deploy_embodiment.EmbodimentConfig)}
    return ours & theirs


def test_the_parsers_share_the_control_fields():
    assert shared_fields() >= SHARED
    for ours, theirs in ((train_embodiment.ActuatorCfg, deploy_embodiment.ActuatorConfig),
                         (train_embodiment.HandChannelCfg, deploy_embodiment.HandChannel)):
        assert [f.name for f in dataclasses.fields(ours)] == [f.name for f in dataclasses.fields(theirs)]


@pytest.mark.parametrize("name", train_embodiment.available_embodiments())
def test_both_parsers_read_every_shipped_embodiment_the_same(name):
    ours = train_embodiment.load_embodiment(name)
    theirs = deploy_embodiment.load_embodiment(name)
    assert theirs.path.resolve() == train_embodiment.resolve_embodiment_path(name).resolve()
    for field in sorted(shared_fields()):
        assert plain(getattr(ours, field)) == plain(getattr(theirs, field)), field
