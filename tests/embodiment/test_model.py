"""Always-on invariants of the generated MuJoCo model and the committed URDF (no reference data needed)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from robot_hoi.embodiment import build_model, build_robot_spec, load_embodiment
from robot_hoi.embodiment.collision import ROBOT_COLLISION_BITS, WORLD_COLLISION_BITS, set_world_collision
from robot_hoi.embodiment.mjcf import DEFAULT_KEYFRAME, mjcf_text
from robot_hoi.embodiment.urdf import COMMITTED_URDF, urdf_text

# Unitree motor order and ranges (G1_INSPIRE_FACTS.md; unitree_ros rev_1_0 MJCF, DFQ URDF for the hands).
BODY_JOINTS = [
    ("left_hip_pitch_joint", -2.5307, 2.8798), ("left_hip_roll_joint", -0.5236, 2.9671),
    ("left_hip_yaw_joint", -2.7576, 2.7576), ("left_knee_joint", -0.087267, 2.8798),
    ("left_ankle_pitch_joint", -0.87267, 0.5236), ("left_ankle_roll_joint", -0.2618, 0.2618),
    ("right_hip_pitch_joint", -2.5307, 2.8798), ("right_hip_roll_joint", -2.9671, 0.5236),
    ("right_hip_yaw_joint", -2.7576, 2.7576), ("right_knee_joint", -0.087267, 2.8798),
    ("right_ankle_pitch_joint", -0.87267, 0.5236), ("right_ankle_roll_joint", -0.2618, 0.2618),
    ("waist_yaw_joint", -2.618, 2.618), ("waist_roll_joint", -0.52, 0.52), ("waist_pitch_joint", -0.52, 0.52),
    ("left_shoulder_pitch_joint", -3.0892, 2.6704), ("left_shoulder_roll_joint", -1.5882, 2.2515),
    ("left_shoulder_yaw_joint", -2.618, 2.618), ("left_elbow_joint", -1.0472, 2.0944),
    ("left_wrist_roll_joint", -1.97222, 1.97222), ("left_wrist_pitch_joint", -1.61443, 1.61443),
    ("left_wrist_yaw_joint", -1.61443, 1.61443),
    ("right_shoulder_pitch_joint", -3.0892, 2.6704), ("right_shoulder_roll_joint", -2.2515, 1.5882),
    ("right_shoulder_yaw_joint", -2.618, 2.618), ("right_elbow_joint", -1.0472, 2.0944),
    ("right_wrist_roll_joint", -1.97222, 1.97222), ("right_wrist_pitch_joint", -1.61443, 1.61443),
    ("right_wrist_yaw_joint", -1.61443, 1.61443),
]
EFFORT = {"hip_pitch": 88, "hip_roll": 139, "hip_yaw": 88, "knee": 139, "ankle": 50, "waist_yaw": 88,
          "waist_roll": 50, "waist_pitch": 50, "shoulder": 25, "elbow": 25, "wrist_roll": 25, "wrist_pitch": 5,
          "wrist_yaw": 5}
HAND_ACTUATED = [("pinky_proximal_joint", 0.0, 1.7), ("ring_proximal_joint", 0.0, 1.7),
                 ("middle_proximal_joint", 0.0, 1.7), ("index_proximal_joint", 0.0, 1.7),
                 ("thumb_proximal_pitch_joint", -0.1, 0.6), ("thumb_proximal_yaw_joint", -0.1, 1.3)]
HAND_PASSIVE = [("thumb_intermediate_joint", "thumb_proximal_pitch_joint", 1.6, 0.0, 0.8),
                ("thumb_distal_joint", "thumb_proximal_pitch_joint", 2.4, 0.0, 1.2),
                ("index_intermediate_joint", "index_proximal_joint", 1.0, 0.0, 1.7),
                ("middle_intermediate_joint", "middle_proximal_joint", 1.0, 0.0, 1.7),
                ("ring_intermediate_joint", "ring_proximal_joint", 1.0, 0.0, 1.7),
                ("pinky_intermediate_joint", "pinky_proximal_joint", 1.0, 0.0, 1.7)]
REQUIRED_SITES = ["left_toe", "right_toe", "head", "imu_in_pelvis"] + [
    f"{s}_{f}_tip" for s in "LR" for f in ("index", "middle", "ring", "pinky", "thumb")]


@pytest.fixture(scope="module")
def cfg():
    return load_embodiment("g1_inspire")


@pytest.fixture(scope="module")
def model(cfg):
    return build_model(cfg)


def test_actuators_in_config_order_with_ranges_and_limits(cfg, model):
    expected = [name for name, _, _ in BODY_JOINTS] + [f"{s}_{n}" for s in "LR" for n, _, _ in HAND_ACTUATED]
    assert model.nu == 41 == len(expected)
    assert [model.actuator(i).name for i in range(model.nu)] == expected == list(cfg.actuator_names)
    ranges = [(lo, hi) for _, lo, hi in BODY_JOINTS] + [(lo, hi) for _ in "LR" for _, lo, hi in HAND_ACTUATED]
    for i, (lo, hi) in enumerate(ranges):
        joint = model.actuator_trnid[i, 0]
        assert model.joint(joint).name == expected[i]
        np.testing.assert_allclose(model.jnt_range[joint], [lo, hi], atol=1e-5, err_msg=expected[i])
        np.testing.assert_allclose(model.actuator_ctrlrange[i], [lo, hi], atol=1e-5)
        assert model.actuator_ctrllimited[i] and model.actuator_forcelimited[i]
    for i, name in enumerate(expected[:29]):
        effort = next(v for k, v in EFFORT.items() if k in name)
        np.testing.assert_allclose(model.actuator_forcerange[i], [-effort, effort])
    np.testing.assert_allclose(model.actuator_forcerange[29:], np.tile([-1.0, 1.0], (12, 1)))


def test_position_actuators_use_config_gains(cfg, model):
    assert (model.actuator_gaintype == mujoco.mjtGain.mjGAIN_FIXED).all()
    assert (model.actuator_biastype == mujoco.mjtBias.mjBIAS_AFFINE).all()
    np.testing.assert_allclose(model.actuator_gainprm[:, 0], cfg.kp)
    np.testing.assert_allclose(model.actuator_biasprm[:, 1], -cfg.kp)
    np.testing.assert_allclose(model.actuator_biasprm[:, 2], -cfg.kd)


def test_joints_and_mimic_equalities(model):
    hinges = [model.joint(j).name for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
    assert len(hinges) == 29 + 24
    assert model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE and model.joint(0).name == "floating_base_joint"
    assert model.body(model.jnt_bodyid[0]).name == "pelvis"
    finger = [n for n in hinges if n[:2] in ("L_", "R_")]
    assert len(finger) == 24
    assert model.neq == 12
    couplings = {(model.joint(model.eq_obj1id[e]).name, model.joint(model.eq_obj2id[e]).name):
                 tuple(model.eq_data[e, :2]) for e in range(model.neq)}
    for side in "LR":
        for passive, driver, ratio, lo, hi in HAND_PASSIVE:
            assert couplings[(f"{side}_{passive}", f"{side}_{driver}")] == pytest.approx((0.0, ratio))
            np.testing.assert_allclose(model.joint(f"{side}_{passive}").range, [lo, hi])


def test_mass_timestep_integrator_and_sites(cfg, model):
    assert model.body_subtreemass[model.body("pelvis").id] == pytest.approx(33.4, rel=0.02)
    assert model.opt.timestep == pytest.approx(cfg.control_dt / cfg.decimation)
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    for name in REQUIRED_SITES:
        assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name) >= 0, name
    for name in ("head",):
        assert model.body(model.site(name).bodyid[0]).name == "torso_link"
    assert not (model.geom_type == mujoco.mjtGeom.mjGEOM_MESH).any(), "collision must be primitives only"
    assert (model.geom_condim[model.geom_contype > 0] == 3).all()


def test_default_keyframe_stands_on_the_floor(cfg, model):
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(DEFAULT_KEYFRAME).id)
    mujoco.mj_forward(model, data)
    assert data.qpos[2] == pytest.approx(cfg.spawn_height)
    np.testing.assert_allclose(data.ctrl, cfg.default_pos)
    floor = model.geom("floor").id
    lowest = min(
        data.geom_xpos[g][2] - np.abs(data.geom_xmat[g].reshape(3, 3) @ model.geom_size[g])[2]
        for g in (model.geom("left_foot").id, model.geom("right_foot").id))
    assert abs(lowest) < 1e-3, f"sole {lowest * 1e3:.2f} mm from the floor"
    feet = {model.geom("left_foot").id, model.geom("right_foot").id}
    touching = {c.geom2 if c.geom1 == floor else c.geom1 for c in data.contact[: data.ncon]}
    assert touching == feet, "only the soles touch the floor in the default stand"
    toe = data.site_xpos[model.site("left_toe").id]
    assert abs(toe[2]) < 2e-3 and toe[0] > 0.1  # front of the sole, on the floor


def _self_contacts(model, data):
    floor = model.geom("floor").id
    return [(model.body(model.geom_bodyid[c.geom1]).name, model.body(model.geom_bodyid[c.geom2]).name)
            for c in data.contact[: data.ncon] if floor not in (c.geom1, c.geom2)]


def test_self_collision_switch(cfg):
    """Arms folded into the torso: contacts only with self-collision on; the floor contacts stay in both."""
    for on in (False, True):
        model = build_model(cfg, self_collision=on)
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, 0)
        mujoco.mj_forward(model, data)
        assert _self_contacts(model, data) == [], "the default stand must be free of self contacts"
        for side, sign in (("left", 1), ("right", -1)):
            data.qpos[model.jnt_qposadr[model.joint(f"{side}_shoulder_roll_joint").id]] = -0.6 * sign
            data.qpos[model.jnt_qposadr[model.joint(f"{side}_elbow_joint").id]] = 0.0
        mujoco.mj_forward(model, data)
        pairs = _self_contacts(model, data)
        assert bool(pairs) == on, pairs
        assert any(model.geom(c.geom1).name == "floor" or model.geom(c.geom2).name == "floor"
                   for c in data.contact[: data.ncon])


def test_objects_added_to_the_spec_touch_the_robot(cfg):
    spec = build_robot_spec(cfg, self_collision=False)
    box = spec.worldbody.add_body(name="box", pos=[0.12, 0.0, 0.1])  # overlaps both toes and the floor
    box.add_freejoint()
    set_world_collision(box.add_geom(name="box_geom", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.1, 0.2, 0.1]))
    model = spec.compile()
    assert model.geom("floor").contype == WORLD_COLLISION_BITS
    assert model.geom("left_foot").contype == ROBOT_COLLISION_BITS
    assert model.body("box").mass[0] > 0  # inertia from the geom still works for added objects
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    mujoco.mj_forward(model, data)
    pairs = {frozenset((model.geom(c.geom1).name, model.geom(c.geom2).name)) for c in data.contact[: data.ncon]}
    assert frozenset(("box_geom", "floor")) in pairs
    assert frozenset(("box_geom", "left_foot")) in pairs and frozenset(("box_geom", "right_foot")) in pairs


def test_committed_urdf_equals_generation(cfg):
    assert COMMITTED_URDF.read_text() == urdf_text(cfg.description()), (
        "urdf/g1_inspire.urdf is stale: run `robot-hoi model urdf -o urdf/g1_inspire.urdf`")


def test_urdf_loads_in_mujoco_with_the_same_kinematics(cfg, model):
    urdf_model = mujoco.MjModel.from_xml_path(str(COMMITTED_URDF))
    assert urdf_model.body_subtreemass[0] == pytest.approx(model.body_subtreemass[1], rel=1e-9)
    assert urdf_model.neq == 12 and urdf_model.njnt == 53  # URDF root is fixed: no free joint
    rng = np.random.default_rng(3)
    d_urdf, d_mjcf = mujoco.MjData(urdf_model), mujoco.MjData(model)
    pelvis_u, pelvis_m = urdf_model.body("pelvis").id, model.body("pelvis").id
    for _ in range(20):
        for j in range(1, model.njnt):
            lo, hi = model.jnt_range[j]
            value = rng.uniform(lo, hi)
            d_mjcf.qpos[model.jnt_qposadr[j]] = value
            d_urdf.qpos[urdf_model.jnt_qposadr[urdf_model.joint(model.joint(j).name).id]] = value
        mujoco.mj_kinematics(model, d_mjcf)
        mujoco.mj_kinematics(urdf_model, d_urdf)
        for name in ("left_ankle_roll_link", "right_wrist_yaw_link", "L_index_intermediate", "R_thumb_distal",
                     "L_index_tip", "R_pinky_tip", "head", "left_toe"):
            rel_m = d_mjcf.xpos[model.body(name).id] if mujoco.mj_name2id(model, 1, name) >= 0 else \
                d_mjcf.site_xpos[model.site(name).id]
            rel_m = d_mjcf.xmat[pelvis_m].reshape(3, 3).T @ (rel_m - d_mjcf.xpos[pelvis_m])
            rel_u = d_urdf.xmat[pelvis_u].reshape(3, 3).T @ (d_urdf.xpos[urdf_model.body(name).id]
                                                             - d_urdf.xpos[pelvis_u])
            np.testing.assert_allclose(rel_u, rel_m, atol=1e-6, err_msg=name)


def test_mjcf_text_loads_standalone(cfg, tmp_path):
    path = tmp_path / "robot.xml"
    path.write_text(mjcf_text(cfg))
    loaded = mujoco.MjModel.from_xml_path(str(path))
    assert (loaded.nq, loaded.nv, loaded.nu, loaded.neq) == (60, 59, 41, 12)
    assert loaded.key(DEFAULT_KEYFRAME).id == 0


def test_urdf_collision_shapes_match_the_mjcf(model):
    """Each capsule's URDF cylinder has the capsule's centre, axis, radius and length; boxes/spheres match."""
    urdf_model = mujoco.MjModel.from_xml_path(str(COMMITTED_URDF))
    d_urdf, d_mjcf = mujoco.MjData(urdf_model), mujoco.MjData(model)
    mujoco.mj_kinematics(urdf_model, d_urdf)
    mujoco.mj_kinematics(model, d_mjcf)
    pelvis_u, pelvis_m = urdf_model.body("pelvis").id, model.body("pelvis").id

    def local(data, pelvis, pos, mat):
        rot = data.xmat[pelvis].reshape(3, 3).T
        return rot @ (pos - data.xpos[pelvis]), rot @ mat.reshape(3, 3)

    checked = 0
    for g in range(model.ngeom):
        name = model.geom(g).name
        if not name or name == "floor":
            continue
        u = urdf_model.geom(name).id
        pos_m, mat_m = local(d_mjcf, pelvis_m, d_mjcf.geom_xpos[g], d_mjcf.geom_xmat[g])
        pos_u, mat_u = local(d_urdf, pelvis_u, d_urdf.geom_xpos[u], d_urdf.geom_xmat[u])
        np.testing.assert_allclose(pos_u, pos_m, atol=1e-6, err_msg=name)
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE:
            assert urdf_model.geom_type[u] == mujoco.mjtGeom.mjGEOM_CYLINDER
            assert abs(abs(mat_u[:, 2] @ mat_m[:, 2]) - 1.0) < 1e-9, name  # same axis
            np.testing.assert_allclose(urdf_model.geom_size[u][:2], model.geom_size[g][:2], atol=1e-6)
        else:
            assert urdf_model.geom_type[u] == model.geom_type[g]
            np.testing.assert_allclose(urdf_model.geom_size[u], model.geom_size[g], atol=1e-6)
        checked += 1
    assert checked == model.ngeom - 1 == 39  # every robot geom (all but the floor)
