"""Our generated model against Unitree's own files (needs ../shared; skipped without it).

Body frames vs g1_29dof_rev_1_0.xml, fingertips vs the DFQ model (derived MJCF + xr_teleoperate tip links),
mass properties per body.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robot_hoi.embodiment import build_model, load_embodiment

pytestmark = pytest.mark.shared

N_CONFIGS = 120


def _load_without_meshes(path) -> mujoco.MjModel:
    """Reference MJCF with its mesh geoms removed (inertials are explicit, so mass properties are unchanged)."""
    spec = mujoco.MjSpec.from_file(str(path))
    for geom in list(spec.geoms):
        if geom.type == mujoco.mjtGeom.mjGEOM_MESH:
            spec.delete(geom)
    for mesh in list(spec.meshes):
        spec.delete(mesh)
    return spec.compile()


@pytest.fixture(scope="module")
def robots(shared):
    folder = shared / "reference" / "robots" / "unitree_g1"
    ours = build_model(load_embodiment("g1_inspire"), floor=False)
    g1 = _load_without_meshes(folder / "g1_29dof_rev_1_0.xml")
    dfq = _load_without_meshes(folder / "g1_29dof_rev_1_0_with_inspire_hand_DFQ.derived.xml")
    return folder, ours, g1, dfq


def _hinges(model):
    return [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]


def _random_state(model, rng) -> dict[str, float]:
    """Random joint angles by name (within ranges; passive finger joints follow their mimic equality)."""
    q = {}
    for j in _hinges(model):
        lo, hi = model.jnt_range[j]
        q[model.joint(j).name] = rng.uniform(lo, hi)
    for e in range(model.neq):
        if model.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT:
            passive, driver = model.joint(model.eq_obj1id[e]).name, model.joint(model.eq_obj2id[e]).name
            q[passive] = model.eq_data[e, 0] + model.eq_data[e, 1] * q[driver]
    return q


def _pose(model, data, base_pos, base_quat_wxyz, q: dict[str, float]) -> None:
    data.qpos[:7] = np.concatenate([base_pos, base_quat_wxyz])
    for name, value in q.items():
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid >= 0:
            data.qpos[model.jnt_qposadr[jid]] = value
    mujoco.mj_kinematics(model, data)


def _angle_deg(qa_wxyz, qb_wxyz) -> float:
    ra = Rotation.from_quat(np.roll(qa_wxyz, -1))
    rb = Rotation.from_quat(np.roll(qb_wxyz, -1))
    return float(np.degrees((ra.inv() * rb).magnitude()))


def test_every_g1_body_frame_matches_unitree(robots):
    _, ours, g1, _ = robots
    rng = np.random.default_rng(0)
    d_ours, d_ref = mujoco.MjData(ours), mujoco.MjData(g1)
    names = [g1.body(i).name for i in range(1, g1.nbody)]
    assert len(names) == 30
    worst_pos, worst_ang = 0.0, 0.0
    for _ in range(N_CONFIGS):
        base_pos = rng.uniform(-1.0, 1.0, 3)
        base_quat_wxyz = np.roll(Rotation.random(random_state=rng).as_quat(), 1)
        q = _random_state(ours, rng)
        _pose(ours, d_ours, base_pos, base_quat_wxyz, q)
        _pose(g1, d_ref, base_pos, base_quat_wxyz, q)
        for name in names:
            a, b = ours.body(name).id, g1.body(name).id
            worst_pos = max(worst_pos, float(np.linalg.norm(d_ours.xpos[a] - d_ref.xpos[b])))
            worst_ang = max(worst_ang, _angle_deg(d_ours.xquat[a], d_ref.xquat[b]))
    assert worst_pos < 1e-3, f"body position off by {worst_pos * 1e3:.3f} mm"
    assert worst_ang < 0.5, f"body orientation off by {worst_ang:.3f} deg"


def _tip_offsets(folder) -> dict[str, tuple[str, np.ndarray]]:
    """tip name -> (parent link, offset) from xr_teleoperate's inspire_hand_left/right.urdf."""
    tips = {}
    for side in ("left", "right"):
        root = ET.parse(folder / f"inspire_hand_{side}.urdf").getroot()
        for joint in root.findall("joint"):
            child = joint.find("child").get("link")
            if child.endswith("_tip"):
                xyz = np.array([float(v) for v in joint.find("origin").get("xyz").split()])
                tips[child] = (joint.find("parent").get("link"), xyz)
    return tips


def test_fingertip_sites_match_dfq_reference(robots):
    folder, ours, _, dfq = robots
    tips = _tip_offsets(folder)
    assert len(tips) == 10
    rng = np.random.default_rng(1)
    d_ours, d_ref = mujoco.MjData(ours), mujoco.MjData(dfq)
    worst = 0.0
    for _ in range(N_CONFIGS):
        base_pos = rng.uniform(-1.0, 1.0, 3)
        base_quat_wxyz = np.roll(Rotation.random(random_state=rng).as_quat(), 1)
        q = _random_state(ours, rng)
        _pose(ours, d_ours, base_pos, base_quat_wxyz, q)
        _pose(dfq, d_ref, base_pos, base_quat_wxyz, q)
        for tip, (parent, offset) in tips.items():
            b = dfq.body(parent).id
            expected = d_ref.xpos[b] + d_ref.xmat[b].reshape(3, 3) @ offset
            worst = max(worst, float(np.linalg.norm(d_ours.site_xpos[ours.site(tip).id] - expected)))
    assert worst < 2e-3, f"fingertip off by {worst * 1e3:.3f} mm"


def _inertia_in_body_frame(model, body_id) -> np.ndarray:
    rot = Rotation.from_quat(np.roll(model.body_iquat[body_id], -1)).as_matrix()
    return rot @ np.diag(model.body_inertia[body_id]) @ rot.T


def _combine(parts) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass, com and inertia about the com of rigidly joined parts [(mass, com, inertia)] in one frame."""
    mass = sum(m for m, _, _ in parts)
    com = sum(m * c for m, c, _ in parts) / mass
    inertia = sum(i + m * (np.dot(c - com, c - com) * np.eye(3) - np.outer(c - com, c - com)) for m, c, i in parts)
    return mass, com, inertia


def test_mass_properties_match_unitree(robots):
    _, ours, g1, dfq = robots
    for i in range(1, g1.nbody):
        name = g1.body(i).name
        if name.endswith("wrist_yaw_link"):
            continue  # the reference still carries the 0.17 kg rubber hand; checked against the DFQ model below
        j = ours.body(name).id
        assert ours.body_mass[j] == pytest.approx(g1.body_mass[i], rel=1e-6), name
        np.testing.assert_allclose(ours.body_ipos[j], g1.body_ipos[i], atol=1e-6, err_msg=name)
        np.testing.assert_allclose(_inertia_in_body_frame(ours, j), _inertia_in_body_frame(g1, i), atol=1e-8,
                                   err_msg=name)
    # DFQ hands: finger links one to one; wrist yaw link + (fixed) hand base against Unitree's fused body.
    for i in range(1, dfq.nbody):
        name = dfq.body(i).name
        if not name.startswith(("L_", "R_")):
            continue
        j = ours.body(name).id
        assert ours.body_mass[j] == pytest.approx(dfq.body_mass[i], rel=1e-6), name
        np.testing.assert_allclose(ours.body_ipos[j], dfq.body_ipos[i], atol=1e-6, err_msg=name)
        np.testing.assert_allclose(_inertia_in_body_frame(ours, j), _inertia_in_body_frame(dfq, i), atol=1e-9,
                                   err_msg=name)
    for side, prefix in (("left", "L"), ("right", "R")):
        wrist, base = ours.body(f"{side}_wrist_yaw_link").id, ours.body(f"{prefix}_hand_base_link").id
        rot = Rotation.from_quat(np.roll(ours.body_quat[base], -1)).as_matrix()
        parts = [
            (ours.body_mass[wrist], ours.body_ipos[wrist], _inertia_in_body_frame(ours, wrist)),
            (ours.body_mass[base], ours.body_pos[base] + rot @ ours.body_ipos[base],
             rot @ _inertia_in_body_frame(ours, base) @ rot.T),
        ]
        mass, com, inertia = _combine(parts)
        ref = dfq.body(f"{side}_wrist_yaw_link").id
        assert mass == pytest.approx(dfq.body_mass[ref], rel=1e-5)  # the derived file keeps 6 digits
        np.testing.assert_allclose(com, dfq.body_ipos[ref], atol=1e-5)
        np.testing.assert_allclose(inertia, _inertia_in_body_frame(dfq, ref), atol=1e-8)
    assert ours.body_subtreemass[1] == pytest.approx(dfq.body_subtreemass[1], abs=1e-5)
