"""Fixtures for the data tests: the synthetic clips (built once) and paths into ../shared's motion folder."""

from __future__ import annotations

from pathlib import Path

import pytest

from robot_hoi.data.synth import default_clip


@pytest.fixture(scope="session")
def lift_clip():
    return default_clip("lift_carry", seed=0)


@pytest.fixture(scope="session")
def push_clip():
    return default_clip("push", seed=0)


@pytest.fixture(scope="session")
def motions(shared) -> Path:
    path = shared / "reference" / "motions"
    if not (path / "clips").is_dir():
        pytest.skip("../shared has no reference/motions/clips")
    return path
