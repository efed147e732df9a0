"""Objects from what a dataset ships: mesh, else URDF geometry, else the hull of sample points, else a box."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
import trimesh

from robot_hoi.cli import main
from robot_hoi.data.clip import load_clip
from robot_hoi.data.objects import load_object_asset
from robot_hoi.errors import DataError


def _folder(tmp_path, name="crate"):
    folder = tmp_path / "objects" / name
    folder.mkdir(parents=True)
    return folder


def _urdf(geometry: str, name="crate", mass: str = "") -> str:
    inertial = f'<inertial><mass value="{mass}"/></inertial>' if mass else ""
    return (f'<robot name="{name}"><link name="base">{inertial}<collision><origin xyz="0 0 0.1" rpy="0 0 0"/>'
            f"<geometry>{geometry}</geometry></collision></link></robot>")


def test_mesh_first(tmp_path):
    folder = _folder(tmp_path)
    trimesh.creation.box(extents=(0.3, 0.2, 0.1)).export(folder / "crate.obj")
    (folder / "crate.urdf").write_text(_urdf('<box size="1 1 1"/>'))
    asset, notes = load_object_asset("crate", tmp_path / "objects", for_file="clip.pt")
    assert np.allclose(asset.extents, (0.3, 0.2, 0.1)) and asset.origin.startswith("mesh ")
    assert notes[0] == f"object 'crate': {asset.origin}"


def test_urdf_box_with_origin_and_mass(tmp_path):
    folder = _folder(tmp_path)
    (folder / "crate.urdf").write_text(_urdf('<box size="0.4 0.3 0.2"/>', mass="3.5"))
    asset, notes = load_object_asset("crate", tmp_path / "objects", for_file="clip.pt")
    assert np.allclose(asset.extents, (0.4, 0.3, 0.2)) and asset.mass_kg == 3.5
    assert np.isclose(asset.vertices[:, 2].max(), 0.2)  # origin xyz moved it up by 0.1
    assert "geometry of" in asset.origin and len(asset.sample_points) > 0
    assert any("sampled" in n for n in notes)  # no sample_points.npy: sampled from the shape


def test_urdf_mesh_resolved_next_to_it(tmp_path):
    folder = _folder(tmp_path)
    trimesh.creation.icosphere(radius=0.1).export(folder / "shape.stl")
    (folder / "crate.urdf").write_text(_urdf('<mesh filename="package://assets/meshes/shape.stl" scale="2 2 2"/>'))
    asset, _ = load_object_asset("crate", tmp_path / "objects", for_file="clip.pt")
    assert np.allclose(asset.extents, 0.4, atol=0.01)


def test_sample_point_hull_when_the_urdf_mesh_is_missing(tmp_path):
    folder = _folder(tmp_path)
    (folder / "crate.urdf").write_text(_urdf('<mesh filename="objects/crate/crate.obj"/>'))
    points = trimesh.sample.sample_surface(trimesh.creation.box(extents=(0.5, 0.4, 0.3)), 300, seed=0)[0]
    np.save(folder / "sample_points.npy", points)
    asset, notes = load_object_asset("crate", tmp_path / "objects", for_file="clip.pt")
    assert asset.origin.startswith("convex hull of") and "crate.urdf names objects/crate/crate.obj" in asset.origin
    assert np.allclose(asset.extents, (0.5, 0.4, 0.3), atol=0.03)
    assert np.array_equal(asset.sample_points, points) and len(notes) == 1


def test_nothing_without_a_clip_names_the_flag(tmp_path):
    _folder(tmp_path)
    with pytest.raises(DataError, match="--objects DIR"):
        load_object_asset("crate", tmp_path / "objects", for_file="clip.pt")


def test_box_from_the_synthetic_clip(tmp_path, lift_clip):
    """lift_carry's box is 0.24 x 0.30 x 0.80 m; a clip saved without it gets a box of about that size."""
    from robot_hoi.data.synth import TALL_BOX_SIZE_M

    clip = lift_clip.copy()
    clip.object = None
    path = clip.save(tmp_path / "clips" / "sub1_box_000.npz")
    loaded = load_clip(path, objects_dir=tmp_path / "none")
    assert "estimated from the clip" in loaded.object.origin
    assert np.all(np.abs(np.sort(loaded.object.extents) - np.sort(TALL_BOX_SIZE_M)) < 0.15)
    assert any(p.startswith("object 'tall_box': box") for p in loaded.problems)


@pytest.mark.slow
@pytest.mark.shared
def test_shared_object_without_its_obj_inspects_retargets_and_trains(motions, tmp_path, capsys):
    """A copy of a shared object folder without the .obj (only URDF + sample points, as some OMOMO objects ship)."""
    shutil.copytree(motions / "objects" / "largebox", tmp_path / "objects" / "largebox",
                    ignore=shutil.ignore_patterns("*.obj"))
    clip_path = motions / "clips" / "sub8_largebox_000.pt"
    objects = str(tmp_path / "objects")
    assert main(["data", "inspect", str(clip_path), "--objects", objects]) == 0
    assert "from convex hull of" in capsys.readouterr().out
    assert main(["retarget", str(clip_path), "--objects", objects, "-o", str(tmp_path / "ref.npz")]) == 0
    capsys.readouterr()
    assert main(["train", "--data", str(clip_path), "--objects", objects, "--budget", "1it", "--skip-gate",
                 "--out", str(tmp_path / "run"), "--eval-episodes", "1",
                 "--set", "env.num_envs=4", "--set", "ppo.horizon=4", "--set", "env.backend=cpu"]) == 0
    assert "object largebox from convex hull" in capsys.readouterr().out
    task = (tmp_path / "run").rglob("task.json").__next__().read_text()
    assert objects in task  # eval / export / sim2sim reload the same object


def test_a_decomposition_is_made_once_and_read_back_from_the_cache(table_object, monkeypatch):
    """CoACD runs once per mesh and settings; later processes (here: the in-process memo emptied) read its file."""
    from robot_hoi.data import objects
    from robot_hoi.data.objects import ObjectAsset

    table = ObjectAsset(name="table", vertices=table_object.vertices + [0.0, 0.0, 1e-3], faces=table_object.faces,
                        sample_points=table_object.sample_points)  # a mesh of its own: not memoised by another test
    folder = objects.decomposition_file("0").parent
    before = set(folder.glob("*.npz"))
    made = table.convex_parts()
    assert len(made) > 1 and len(set(folder.glob("*.npz")) - before) == 1  # its file
    monkeypatch.setattr(objects, "_DECOMPOSITIONS", {})
    monkeypatch.setattr(objects, "_decompose", lambda *a: pytest.fail("decomposed again"))
    again = table.convex_parts()
    assert len(again) == len(made) and all(np.array_equal(a, b) for a, b in zip(again, made, strict=True))
