"""An object that is not convex (a table) collides as its convex pieces: the retarget's distances, the simulated
geoms and the mass all follow the `object_collision` choice."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from robot_hoi.data.objects import ObjectAsset, box_asset
from robot_hoi.errors import DataError
from robot_hoi.retarget.object_contact import HullPlanes
from robot_hoi.sim.scene import OBJECT_BODY, add_object

TOP_Z = 0.40  # the table_object fixture's top spans 0.40-0.45 m

@pytest.mark.slow
def test_a_table_decomposes_into_pieces_that_leave_room_under_its_top(table_object):
    table = table_object

    pieces = table.convex_parts()
    assert 2 <= len(pieces) <= 16
    hull, decomposed = HullPlanes.from_vertices(table.vertices), HullPlanes.from_pieces(pieces)
    under_top = np.array([[0.0, 0.0, 0.2], [0.2, -0.1, 0.3]])  # between the legs
    assert np.all(hull.signed_distance(under_top)[0] < -0.05)  # "inside" the hull
    assert np.all(decomposed.signed_distance(under_top)[0] > 0.05)  # clear of every piece
    in_top = np.array([[0.1, 0.1, TOP_Z + 0.04]])  # 1 cm under the top's upper face (CoACD adds ~5 mm)
    dist, face = decomposed.signed_distance(in_top)
    assert -0.02 < dist[0] < -0.005
    np.testing.assert_allclose(decomposed.normals[face[0]], [0.0, 0.0, 1.0], atol=0.05)
    out = decomposed.push_out(in_top, clearance=0.01)
    np.testing.assert_allclose(out[0], [0.1, 0.1, TOP_Z + 0.065], atol=0.007)  # straight up, out of the top
    assert decomposed.signed_distance(out)[0][0] >= 0.01 - 1e-9
    # the same pieces every time (CoACD is seeded), and the cached copy cannot be edited through the result
    again = ObjectAsset(name="copy", vertices=table.vertices.copy(), faces=table.faces.copy(),
                        sample_points=table.sample_points).convex_parts()
    assert [len(p) for p in again] == [len(p) for p in pieces]
    pieces[0][:] = 0.0
    assert np.abs(table.convex_parts()[0]).max() > 0


def test_a_convex_object_is_its_own_single_piece():
    box = box_asset((0.3, 0.4, 0.5))
    (piece,) = box.convex_parts()
    np.testing.assert_allclose(np.sort(piece, axis=0), np.sort(box.hull_vertices(), axis=0))
    with pytest.raises(DataError, match="object_collision must be one of hull, decomposed"):
        box.collision_pieces("mesh")
    # "decomposed" builds the very same simulated box as "hull" (the shipped policies were trained on the hull)
    models = [_scene(box, pieces)[0] for pieces in (None, box.collision_pieces("decomposed"))]
    for field in ("geom_size", "geom_rbound", "mesh_vert", "body_mass", "body_inertia"):
        np.testing.assert_array_equal(getattr(models[0], field), getattr(models[1], field))


def _scene(table: ObjectAsset, pieces):
    spec = mujoco.MjSpec()
    add_object(spec, table.vertices, table.faces, density=25.0, friction=0.9, contype=1, conaffinity=1,
               pieces=pieces)
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qpos[:3] = 0.0  # the table stands at the origin
    mujoco.mj_forward(model, data)
    return model, data


def test_the_simulated_table_has_room_under_its_top_and_keeps_its_mass(table_object):
    table = table_object
    hull_model, hull_data = _scene(table, None)
    pieces_model, pieces_data = _scene(table, table.convex_parts())
    body = mujoco.mj_name2id(pieces_model, mujoco.mjtObj.mjOBJ_BODY, OBJECT_BODY)
    assert pieces_model.body_geomnum[body] == len(table.convex_parts())
    assert hull_model.body_geomnum[body] == 1
    assert pieces_model.body_mass[body] == pytest.approx(hull_model.body_mass[body])  # the solid hull's mass
    # a horizontal ray under the top, between the legs: the hull is hit from outside, the pieces are not
    geom = np.zeros(1, dtype=np.int32)
    start, direction = np.array([-1.0, 0.0, 0.2]), np.array([1.0, 0.0, 0.0])
    assert mujoco.mj_ray(hull_model, hull_data, start, direction, None, 1, -1, geom) == pytest.approx(0.7, abs=0.01)
    assert mujoco.mj_ray(pieces_model, pieces_data, start, direction, None, 1, -1, geom) == -1
    # ... while a ray down onto the top hits it in both
    down = np.array([0.0, 0.0, -1.0])
    for model, data in ((hull_model, hull_data), (pieces_model, pieces_data)):
        assert mujoco.mj_ray(model, data, np.array([0.1, 0.1, 1.0]), down, None, 1, -1, geom) == pytest.approx(
            1.0 - TOP_Z - 0.05, abs=0.01)
