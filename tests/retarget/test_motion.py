"""RobotMotion files: npz + JSON round trip, no pickles, clear errors."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest

from robot_hoi.errors import DataError
from robot_hoi.retarget.motion import RobotMotion, finite_difference_qvel


def _motion(T=5, L=3, A=4, nq=11, nv=10) -> RobotMotion:
    rng = np.random.default_rng(1)
    quat = rng.normal(size=(T, L, 4))
    return RobotMotion(
        fps=30.0,
        qpos=rng.normal(size=(T, nq)),
        qvel=rng.normal(size=(T, nv)),
        joint_pos=rng.normal(size=(T, A)),
        link_pos=rng.normal(size=(T, L, 3)),
        link_quat_wxyz=quat / np.linalg.norm(quat, axis=-1, keepdims=True),
        target_pos=rng.normal(size=(T, L, 3)),
        object_pos=rng.normal(size=(T, 3)),
        object_quat_wxyz=np.tile([1.0, 0.0, 0.0, 0.0], (T, 1)),
        anchor=rng.uniform(size=(T, L)),
        residual=rng.uniform(size=(T, L)),
        link_names=("a", "b", "c"),
        human_names=("Pelvis", "L_Wrist", "R_Wrist"),
        actuator_names=("j0", "j1", "j2", "j3"),
        embodiment="toy",
        scale=0.68,
        meta={"report": {"frames": T}},
    )


def test_round_trip(tmp_path):
    m = _motion()
    npz, side = m.save(tmp_path / "sub" / "m.npz")
    assert npz.is_file() and side == tmp_path / "sub" / "m.json"
    assert sorted(p.name for p in npz.parent.iterdir()) == ["m.json", "m.npz"]  # no temp files left
    back = RobotMotion.load(npz)
    np.testing.assert_array_equal(back.qpos, m.qpos)  # float64 kept for the state
    for name in ("qvel", "joint_pos", "link_pos", "link_quat_wxyz", "target_pos", "anchor", "residual"):
        np.testing.assert_allclose(getattr(back, name), getattr(m, name), atol=1e-6)
    assert back.link_names == m.link_names and back.actuator_names == m.actuator_names
    assert back.fps == 30.0 and back.scale == pytest.approx(0.68) and back.embodiment == "toy"
    assert back.meta["report"]["frames"] == 5
    assert json.loads(side.read_text())["quaternion_convention"] == "wxyz"


def test_source_object_path_is_kept_and_older_files_default_to_the_object_path(tmp_path):
    m = _motion()
    np.testing.assert_array_equal(m.source_object_pos, m.object_pos)  # nothing moved the object
    moved = RobotMotion(**{**m.__dict__, "source_object_pos": m.object_pos + 0.1})
    back = RobotMotion.load(moved.save(tmp_path / "moved.npz")[0])
    np.testing.assert_allclose(back.source_object_pos, m.object_pos + 0.1, atol=1e-6)
    np.testing.assert_allclose(back.object_pos, m.object_pos, atol=1e-6)
    npz, _ = m.save(tmp_path / "old.npz")
    with np.load(npz) as data:  # a file written before the field existed
        arrays = {k: data[k] for k in data.files if not k.startswith("source_")}
    np.savez(npz, **arrays)
    old = RobotMotion.load(npz)
    np.testing.assert_allclose(old.source_object_quat_wxyz, old.object_quat_wxyz)


def test_shape_mismatch_is_rejected():
    m = _motion()
    with pytest.raises(DataError, match="anchor"):
        RobotMotion(**{**m.__dict__, "anchor": np.zeros((5, 2))})
    with pytest.raises(DataError, match="joint_pos"):
        RobotMotion(**{**m.__dict__, "actuator_names": ("j0",)})


def test_load_errors_name_the_file(tmp_path):
    with pytest.raises(DataError, match="no such motion file"):
        RobotMotion.load(tmp_path / "missing.npz")
    npz, side = _motion().save(tmp_path / "m.npz")
    side.write_text("{not json")
    with pytest.raises(DataError, match="not valid JSON"):
        RobotMotion.load(npz)
    _motion().save(tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz") as npz_file:
        arrays = dict(npz_file)
    arrays["qpos"] = np.array([{"evil": 1}] * 5, dtype=object)  # a pickle inside: must be refused, not run
    np.savez(tmp_path / "m.npz", **arrays)
    with pytest.raises(DataError, match="not a readable npz"):
        RobotMotion.load(tmp_path / "m.npz")
    with pytest.raises(DataError, match=".npz"):
        _motion().save(tmp_path / "m.npy")


def test_finite_difference_qvel_on_a_free_body():
    model = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body><freejoint/><geom size='0.1'/></body></worldbody></mujoco>")
    T, fps = 6, 30.0
    qpos = np.zeros((T, 7))
    t = np.arange(T) / fps
    qpos[:, 0] = 0.5 * t  # 0.5 m/s along x
    half = 0.5 * 1.2 * t  # yaw at 1.2 rad/s
    qpos[:, 3], qpos[:, 6] = np.cos(half), np.sin(half)
    qvel = finite_difference_qvel(model, qpos, fps)
    np.testing.assert_allclose(qvel[:, 0], 0.5, atol=1e-9)
    np.testing.assert_allclose(qvel[:, 5], 1.2, atol=1e-9)
