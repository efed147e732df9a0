"""Shared fixtures. Tests that need ../shared reference data use `shared` and skip cleanly without it."""

from __future__ import annotations

from pathlib import Path

import pytest

from robot_hoi.paths import shared_dir


@pytest.fixture(scope="session")
def shared() -> Path:
    path = shared_dir()
    if path is None:
        pytest.skip("../shared reference folder is absent")
    return path
