"""Executable-reference helpers: speed limit, smoothing, grasp squeeze; kinematic feasibility measures."""

from __future__ import annotations

import numpy as np
import pytest

from robot_hoi.retarget.executable import ExecutableSettings, limit_speed, smooth_joints
from robot_hoi.retarget.feasibility import foot_slide, support_distance


def test_limit_speed_caps_every_step_and_keeps_slow_tracks():
    track = np.zeros((20, 2))
    track[10:, 0] = 1.0  # a 1 rad jump between two frames
    track[:, 1] = np.linspace(0.0, 0.19, 20)  # 0.01 per frame: untouched
    out = limit_speed(track, 0.1)
    assert np.abs(np.diff(out, axis=0)).max() <= 0.1 + 1e-12
    np.testing.assert_allclose(out[:, 1], track[:, 1])
    assert out[0, 0] == pytest.approx(0.0, abs=0.06) and out[-1, 0] == pytest.approx(1.0, abs=0.06)
    assert 0.3 < out[10, 0] < 0.7  # the jump is spread around where it happened (no phase lag)


def test_smooth_joints_only_touches_the_given_columns():
    rng = np.random.default_rng(0)
    qpos = rng.normal(size=(30, 5))
    out = smooth_joints(qpos, np.array([1, 3]), fps=30.0, settings=ExecutableSettings(max_joint_speed=3.0))
    np.testing.assert_array_equal(out[:, [0, 2, 4]], qpos[:, [0, 2, 4]])
    assert np.abs(np.diff(out[:, [1, 3]], axis=0)).max() <= 3.0 / 30.0 + 1e-9


def test_foot_slide_counts_only_frames_on_the_floor():
    soles = np.zeros((4, 3, 3))
    soles[:, :, 0] = np.array([0.0, 0.1, 0.3, 0.3])[:, None]  # moves 10 cm, then 20 cm
    soles[2:, :, 2] = 0.05  # ... but the 20 cm happen with the foot lifted
    assert foot_slide(soles) == pytest.approx(0.1)


def test_support_distance_inside_and_outside():
    square = np.array([[0.0, 0.0], [0.2, 0.0], [0.2, 0.1], [0.0, 0.1]])
    assert support_distance(np.array([0.1, 0.05]), square) == pytest.approx(-0.05)
    assert support_distance(np.array([0.3, 0.05]), square) == pytest.approx(0.1)
    assert support_distance(np.array([0.0, 0.0]), square[:2]) == np.inf  # no polygon: not supported


def test_synthetic_lift_place_reference_is_executable():
    """The embedded first clip: feet planted, CoM over the feet, joint speeds a PD robot can follow, and the
    grasp squeeze only on the arm PD targets."""
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.tasks.interaction import factory

    embodiment = load_embodiment("g1_inspire")
    motion = factory.load_or_retarget(factory.load_source("embedded:lift_place"), embodiment, None)
    f = motion.meta["feasibility"]
    assert max(f["foot_slide_cm"].values()) < 6.0
    assert f["com_outside_support_fraction"] < 0.05
    assert f["joint_speed_p99_rad_s"] < 12.0


def test_hand_size_fit_brings_the_wrists_to_their_targets():
    """The Inspire hand is ~1.65x a human hand: fitted about the palm, the held wrists' IK residuals on the
    embedded lift_place clip are far smaller than with the human hand mapped 1:1 (measured: ~6 vs ~11 cm)."""
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.retarget.pipeline import RetargetOptions, retarget_clip
    from robot_hoi.retarget.targets import TargetMapping
    from robot_hoi.tasks.interaction import factory

    embodiment = load_embodiment("g1_inspire")
    clip = factory.load_source("embedded:lift_place")
    fitted = factory.load_or_retarget(clip, embodiment, None)
    plain = retarget_clip(clip, embodiment, options=RetargetOptions(mapping=TargetMapping(hand_size_fit=False))).motion
    wrists = [fitted.link_names.index(n) for n in ("left_wrist_yaw_link", "right_wrist_yaw_link")]
    tips = [i for i, n in enumerate(fitted.link_names) if n.endswith("_tip") and "thumb" not in n]
    held = fitted.anchor[:, tips].min(axis=1) > 0.5  # every finger on the box
    assert held.sum() > 30
    fitted_residual = fitted.residual[held][:, wrists].mean()
    plain_residual = plain.residual[held][:, wrists].mean()
    assert fitted_residual < 0.75 * plain_residual, (fitted_residual, plain_residual)


def test_planted_feet_are_pinned():
    """A foot target that jitters while down is held at its stretch's mean with a raised IK weight; a moving foot
    is left alone."""
    from robot_hoi.retarget.targets import TargetMapping, pin_feet, planted

    fps = 30.0
    t = np.arange(60)
    pos = np.zeros((60, 2, 3))
    pos[:, 0, 0] = 0.004 * np.sin(t)            # link 0: down, jittering by 4 mm
    pos[:, 1, 0] = np.linspace(0.0, 1.2, 60)    # link 1: moving 0.6 m/s (walking, not planted)
    pos[:, 1, 2] = 0.1
    weight = np.ones((60, 2))
    assert planted(pos, fps, 0.03, 0.25)[:, 0].all() and not planted(pos, fps, 0.03, 0.25)[:, 1].any()
    pin_feet(pos, weight, [0, 1], fps, TargetMapping())
    assert np.ptp(pos[:, 0, 0]) == 0.0 and (weight[:, 0] == 11.0).all()
    np.testing.assert_allclose(pos[:, 1, 0], np.linspace(0.0, 1.2, 60))
    assert (weight[:, 1] == 1.0).all()


def test_foot_slide_ignores_steps_when_told_where_feet_are_planted():
    soles = np.zeros((4, 3, 3))
    soles[:, :, 0] = np.array([0.0, 0.1, 0.3, 0.3])[:, None]
    planted_flags = np.array([False, False, True, True])  # the first moves are a step's lift-off, not a slide
    assert foot_slide(soles, planted=planted_flags) == pytest.approx(0.0)


def test_load_offsets_hold_the_pose_a_pd_servo_would_sag_from():
    """A horizontal 1 kg arm under a kp 50 position servo: targeting the pose itself it sags ~0.05 rad; with the
    gravity offset it settles on the pose; a weight carried at the tip adds its torque over kp."""
    import mujoco

    from robot_hoi.retarget.executable import load_offsets

    xml = """<mujoco><option timestep="0.002"/><worldbody><body name="arm">
      <joint name="shoulder" type="hinge" axis="0 1 0" damping="1"/>
      <geom type="capsule" fromto="0 0 0 0.5 0 0" size="0.02" mass="1"/>
      <body name="tip" pos="0.5 0 0"/></body></worldbody>
      <actuator><position joint="shoulder" kp="50"/></actuator></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    pose = np.zeros((1, 1))

    def settle(target):
        data = mujoco.MjData(model)
        data.ctrl[:] = target
        for _ in range(3000):
            mujoco.mj_step(model, data)
        return float(data.qpos[0])

    sag = settle(0.0)
    assert abs(sag) > 0.04  # gravity (1 kg at 0.25 m) over kp 50: 0.049 rad
    offset = load_offsets(model, pose, ["shoulder"], {})
    assert abs(settle(offset[0, 0])) < 0.1 * abs(sag)
    carried = load_offsets(model, pose, ["shoulder"], {"tip": np.array([5.0])})  # 5 N held at the tip
    assert abs(carried[0, 0]) > abs(offset[0, 0]) + 0.04  # 5 N x 0.5 m / 50 = 0.05 rad more


def test_dynamic_load_offsets_let_a_pd_servo_follow_a_fast_swing():
    """The same arm swinging +-0.5 rad at 1.5 Hz under a kp 50, kv 2 position servo: with the static (gravity)
    offsets it lags the swing (inertia and the servo's damping); with the inverse-dynamics offsets along the motion
    (compensate_dynamics) it follows it several times closer."""
    import mujoco

    from robot_hoi.retarget.executable import load_offsets

    xml = """<mujoco><option timestep="0.001"/><worldbody><body name="arm">
      <joint name="shoulder" type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0.5 0 0" size="0.02" mass="1"/></body></worldbody>
      <actuator><position joint="shoulder" kp="50" kv="2"/></actuator></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    fps, w = 100.0, 2 * np.pi * 1.5
    t = np.arange(300) / fps
    qpos, qvel, qacc = 0.5 * np.sin(w * t), 0.5 * w * np.cos(w * t), -0.5 * w * w * np.sin(w * t)

    def worst_lag(offsets):
        data = mujoco.MjData(model)
        data.qpos[0], data.qvel[0] = qpos[0], qvel[0]
        lag = []
        for k in range(len(t) - 1):
            data.ctrl[0] = qpos[k + 1] + offsets[k + 1, 0]  # the env targets the frame the step moves to
            for _ in range(10):
                mujoco.mj_step(model, data)
            lag.append(abs(data.qpos[0] - qpos[k + 1]))
        return max(lag[100:])  # after a second of settling

    static = worst_lag(load_offsets(model, qpos[:, None], ["shoulder"], {}))
    dynamic = worst_lag(load_offsets(model, qpos[:, None], ["shoulder"], {}, motion=(qvel[:, None], qacc[:, None])))
    assert static > 0.1
    assert dynamic < 0.25 * static


def test_lift_place_grip_keeps_the_wrists_below_the_box_top():
    """The embedded clip grips the box's sides well below its top: with the grip near the top the Inspire wrists
    rested on the box and pressed it into the floor (measured 130 N per hand) instead of lifting it."""
    from robot_hoi.data.synth import TALL_BOX_SIZE_M
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.tasks.interaction import factory

    motion = factory.load_or_retarget(factory.load_source("embedded:lift_place"), load_embodiment("g1_inspire"), None)
    wrists = [motion.link_names.index(n) for n in ("left_wrist_yaw_link", "right_wrist_yaw_link")]
    held = motion.anchor[:, wrists].min(axis=1) > 0.5
    assert held.sum() > 30
    top = motion.object_pos[held, 2] + TALL_BOX_SIZE_M[2] / 2
    assert (motion.link_pos[held][:, wrists, 2] < top[:, None] - 0.15).all()


def test_self_penetration_finds_a_hand_pushed_into_the_thigh():
    from robot_hoi.embodiment import build_model, load_embodiment
    from robot_hoi.retarget.feasibility import self_penetration

    emb = load_embodiment("g1_inspire")
    model = build_model(emb, self_collision=True)
    stand = np.asarray(model.qpos0, dtype=float).copy()
    stand[:7] = [0, 0, 0.8, 1, 0, 0, 0]
    for name, value in zip(emb.actuator_names, emb.default_pos, strict=True):
        stand[model.jnt_qposadr[model.joint(name).id]] = value
    assert self_penetration(model, stand[None])["self_penetration_fraction"] == 0.0  # the default stand is clear
    inward = stand.copy()  # left arm swung across the body: the hand ends inside the thighs / pelvis
    inward[model.jnt_qposadr[model.joint("left_shoulder_roll_joint").id]] = -0.6
    inward[model.jnt_qposadr[model.joint("left_elbow_joint").id]] = 0.0
    report = self_penetration(model, np.stack([stand, inward]))
    assert report["self_penetration_cm"] > 1.0 and report["self_penetration_fraction"] == 0.5
    assert any("left" in pair or "pelvis" in pair or "torso" in pair for pair in report["self_penetration_pairs"])


def test_leg_load_offsets_carry_a_crouched_robot_on_its_feet():
    """The G1 crouched (knees 1 rad) on its PD servos: targeting the pose, the pelvis sags 9 cm (the knees yield
    to the body's weight); with the offsets of the load carried through the soles on the floor, under 1 cm."""
    import mujoco

    from robot_hoi.data.objects import box_asset
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.retarget.executable import load_offsets
    from robot_hoi.retarget.ik import sole_points
    from robot_hoi.tasks.interaction.scene_setup import InteractionScene

    embodiment = load_embodiment("g1_inspire")
    scene = InteractionScene(embodiment, box_asset((0.4, 0.4, 0.3)))
    model = scene.model
    qpos = model.qpos0.copy()
    qpos[: scene.layout.robot_nq] = scene.default_robot_qpos()[0].double().numpy()
    qpos[scene.layout.object_qpos:scene.layout.object_qpos + 3] = (3.0, 0.0, 0.15)  # out of the way
    for side in ("left", "right"):
        for joint, angle in (("hip_pitch", -0.5), ("knee", 1.0), ("ankle_pitch", -0.5)):
            qpos[model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"{side}_{joint}_joint")]] = angle
    feet = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"{side}_ankle_roll_link") for side in ("left", "right")]
    sole_body, sole_local = sole_points(model, qpos, feet)
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    soles = data.xpos[sole_body] + np.einsum("pij,pj->pi", data.xmat[sole_body].reshape(-1, 3, 3), sole_local)
    qpos[2] -= soles[:, 2].min()  # standing on the floor
    legs = [n for n in embodiment.actuator_names if any(k in n for k in ("hip", "knee", "ankle"))]
    targets = model.jnt_qposadr[model.actuator_trnid[:, 0]]

    def sag(offsets):
        data = mujoco.MjData(model)
        data.qpos[:] = qpos
        data.ctrl[:] = qpos[targets] + offsets[targets]
        for _ in range(int(1.0 / model.opt.timestep)):
            mujoco.mj_step(model, data)
        return qpos[2] - data.qpos[2]

    assert sag(np.zeros(model.nq)) > 0.05
    assert sag(load_offsets(model, qpos[None], legs, {}, (sole_body, sole_local))[0]) < 0.01


@pytest.mark.slow
def test_hold_test_starts_just_before_the_grip_not_at_the_walk_up(monkeypatch):
    """From frame 0, the zero-residual replay of lift_carry had to survive a 1.2 m walk-up first and fell before the
    hands ever held the box (0 held frames): the test said nothing about the grasp. The root is held in the replay:
    the assist's per-episode draw (half of the training episodes) had left it free."""
    from robot_hoi.data.synth import embedded_clip
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.paths import TASK_CONFIG
    from robot_hoi.tasks.interaction import factory
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
    from robot_hoi.tasks.interaction.feasibility import physics_gate
    from robot_hoi.utils.config import load_yaml_dataclass

    envs, make_env = [], factory.make_env
    monkeypatch.setattr(factory, "make_env", lambda *a, **k: envs.append(make_env(*a, **k)) or envs[-1])
    result = physics_gate(embedded_clip("lift_carry"), load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG),
                       load_embodiment("g1_inspire"), lead_frames=10)
    assert result["first_held_frame"] > 60  # after the walk-up
    assert result["start_frame"] == result["first_held_frame"] - 10
    assert result["frames_held"] > 0
    assert result["completed"] or result["ended_by"] in ("object_deviation", "contact_lost", "link_deviation",
                                                         "interaction_distance", "root_too_low")
    assert len(envs) == 1 and bool(envs[0].assisted.all())


def _squeeze_depth_gain(result, model) -> float:
    """Mean over the squeezed frames of how much deeper the hands' collision spheres reach into the object at the
    PD-target pose than at the reference pose (m)."""
    import mujoco

    from robot_hoi.retarget.object_contact import hand_probe_points

    motion, hull = result.motion, result.targets.object_hull
    wrists = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"{s}_wrist_yaw_link") for s in ("left", "right")]
    probes = hand_probe_points(model, wrists)
    act_qadr = model.jnt_qposadr[model.actuator_trnid[:, 0]]
    squeezed = np.flatnonzero(np.abs(motion.joint_pos - motion.qpos[:, act_qadr]).max(axis=1) > 1e-6)
    data = mujoco.MjData(model)

    def depth(qpos, t):
        data.qpos[:] = qpos
        mujoco.mj_kinematics(model, data)
        world = data.xpos[probes.body_ids] + np.einsum("nij,nj->ni", data.xmat[probes.body_ids].reshape(-1, 3, 3),
                                                       probes.local)
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, motion.object_quat_wxyz[t])
        dist, _ = hull.signed_distance((world - motion.object_pos[t]) @ rot.reshape(3, 3))
        return float((probes.radius - dist).max())

    gains = []
    for t in squeezed:
        target = motion.qpos[t].copy()
        target[act_qadr] = motion.joint_pos[t]
        gains.append(depth(target, t) - depth(motion.qpos[t], t))
    assert len(gains) > 30
    return float(np.mean(gains))


def test_surface_squeeze_presses_the_hands_into_the_object():
    """squeeze_toward="surface": a holding hand's PD targets go into the object's nearest face, so a push presses
    on the box. Toward the other hand (the default), the hands of embedded:push, which rest on the box's top edge,
    slide along it instead."""
    from dataclasses import replace

    from robot_hoi.embodiment import build_model, load_embodiment
    from robot_hoi.retarget.pipeline import RetargetOptions, retarget_clip
    from robot_hoi.tasks.interaction import factory

    embodiment = load_embodiment("g1_inspire")
    model = build_model(embodiment)
    clip = factory.load_source("embedded:push")
    gains = {}
    for toward in ("other_hand", "surface"):
        options = RetargetOptions()
        options = replace(options, executable=replace(options.executable, compensate_loads=False,
                                                      squeeze_toward=toward))
        gains[toward] = _squeeze_depth_gain(retarget_clip(clip, embodiment, model, options=options), model)
    assert gains["surface"] > 0.03
    assert gains["surface"] > gains["other_hand"] + 0.01
