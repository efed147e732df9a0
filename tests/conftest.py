"""Shared fixtures. Tests that need ../shared reference data use `shared` and skip cleanly without it."""

from __future__ import annotations

from pathlib import Path

import pytest

from robot_hoi.paths import shared_dir


@pytest.fixture(scope="session", autouse=True)
def _cache_of_this_session(tmp_path_factory):
    """Kept results (object decompositions) go to a folder of this test session: none are read from the user's."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROBOT_HOI_CACHE", str(tmp_path_factory.mktemp("cache")))
        yield


@pytest.fixture(scope="session")
def shared() -> Path:
    path = shared_dir()
    if path is None:
        pytest.skip("../shared reference folder is absent")
    return path


@pytest.fixture(scope="session")
def table_object():
    """A procedural object that is not convex: a 0.6 x 0.6 m table, its 5 cm top (0.40-0.45 m) on four 5 cm legs."""
    import numpy as np
    import trimesh

    from robot_hoi.data.objects import ObjectAsset

    top = trimesh.creation.box(extents=(0.6, 0.6, 0.05))
    top.apply_translation((0.0, 0.0, 0.425))
    parts = [top]
    for x in (-0.275, 0.275):
        for y in (-0.275, 0.275):
            leg = trimesh.creation.box(extents=(0.05, 0.05, 0.40))
            leg.apply_translation((x, y, 0.20))
            parts.append(leg)
    mesh = trimesh.util.concatenate(parts)
    points, _ = trimesh.sample.sample_surface(mesh, 300, seed=0)
    return ObjectAsset(name="table", vertices=np.asarray(mesh.vertices), faces=np.asarray(mesh.faces),
                       sample_points=np.asarray(points))
