"""The simulated robot world: the motor drivers' PD law, effort limits, latency, gain mismatch, gantry, pushes
and model perturbations."""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np
import pytest

from sim2sim.perturbations import ALL, NOMINAL


def _command(world, contract, q=None, kp_scale=1.0, tau=None):
    n = contract.num_body
    q = contract.default_pose[:n] if q is None else q
    world.command(q, np.zeros(n), kp_scale * contract.kp[:n], contract.kd[:n], np.zeros(n) if tau is None else tau)


def test_validation_model_has_motors_and_the_validation_physics(make_world, contract):
    world = make_world()
    m = world.model
    assert np.all(m.actuator_biastype[world.layout.body_act] == mujoco.mjtBias.mjBIAS_NONE)  # motors, no built-in PD
    assert np.all(m.actuator_biastype[world.layout.hand_act] == mujoco.mjtBias.mjBIAS_AFFINE)  # hand servos
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER and m.opt.timestep == pytest.approx(0.002)
    np.testing.assert_allclose(world.layout.effort, contract.effort_limit[: contract.num_body])


def test_pd_law_at_the_pd_rate(make_world, contract):
    world = make_world()
    n = contract.num_body
    world.advance_to(0.1)
    rng = np.random.default_rng(0)
    q_target = contract.default_pose[:n] + rng.uniform(-0.05, 0.05, n)
    tau_ff = rng.uniform(-1.0, 1.0, n)
    dq_target = rng.uniform(-0.1, 0.1, n)
    world.command(q_target, dq_target, contract.kp[:n], contract.kd[:n], tau_ff)
    lay = world.layout
    q, dq = world.data.qpos[lay.body_qpos].copy(), world.data.qvel[lay.body_dof].copy()
    world.advance_to(world.t + world.pd_dt)  # exactly one PD update
    expected = contract.kp[:n] * (q_target - q) + contract.kd[:n] * (dq_target - dq) + tau_ff
    np.testing.assert_allclose(world.data.ctrl[lay.body_act], np.clip(expected, -lay.effort, lay.effort), rtol=1e-9)
    # the torque is held between updates (zero-order hold): ctrl changes only at the next update
    held = world.data.ctrl[lay.body_act].copy()
    mujoco.mj_step(world.model, world.data)
    np.testing.assert_array_equal(world.data.ctrl[lay.body_act], held)


def test_torques_are_effort_limited(make_world, contract):
    world = make_world()
    n = contract.num_body
    far = contract.default_pose[:n] + 0.5
    world.command(far, np.zeros(n), 100 * contract.kp[:n], contract.kd[:n], np.zeros(n))
    world.advance_to(0.01)
    ctrl = world.data.ctrl[world.layout.body_act]
    assert np.all(np.abs(ctrl) <= world.layout.effort + 1e-12)
    assert np.any(np.isclose(np.abs(ctrl), world.layout.effort))
    assert world.torque_saturated_updates > 0


def test_actuator_latency_delays_the_command(make_world, contract):
    world = make_world(replace(NOMINAL, actuator_latency_s=0.02))
    _command(world, contract)
    world.advance_to(0.018)
    assert np.all(world.data.ctrl[world.layout.body_act] == 0.0)  # drivers still on their power-up (no) command
    world.advance_to(0.03)
    assert np.any(world.data.ctrl[world.layout.body_act] != 0.0)


def test_gain_mismatch_scales_the_applied_torque(make_world, contract):
    n = contract.num_body
    torques = []
    for scale in (1.0, 0.5):
        world = make_world(replace(NOMINAL, kp_scale=scale, kd_scale=scale))
        world.command(contract.default_pose[:n] + 0.01, np.zeros(n), contract.kp[:n], contract.kd[:n], np.zeros(n))
        world.advance_to(world.pd_dt)
        torques.append(world.data.ctrl[world.layout.body_act].copy())
    np.testing.assert_allclose(torques[1], 0.5 * torques[0], rtol=1e-6, atol=1e-9)


def test_gantry_holds_until_released_and_the_pd_holds_the_stand(make_world, contract):
    world = make_world()
    z0 = world.data.qpos[2]
    world.advance_to(0.5)  # no command: motors off, the gantry carries the robot
    assert abs(world.data.qpos[2] - z0) < 0.01
    _command(world, contract)
    world.advance_to(1.0)
    world.release_gantry()
    assert world.gantry_released_at == pytest.approx(1.0)
    world.advance_to(3.0)
    assert world.data.qpos[2] > z0 - 0.03  # the default stand holds by PD alone (ankle kp 300)

    limp = make_world()
    limp.release_gantry()
    limp.advance_to(1.0)
    assert limp.data.qpos[2] < z0 - 0.2  # without torque it collapses


def test_model_perturbations(make_world, target):
    nominal, heavy = make_world(), make_world(ALL["object_mass_x10"])
    obj = nominal.layout.object_body
    assert heavy.model.body_mass[obj] == pytest.approx(10 * nominal.model.body_mass[obj])
    assert nominal.model.body_mass[obj] == pytest.approx(target.object_mass_kg)
    slippery = make_world(ALL["friction_x0.5"])
    geoms = nominal.layout.friction_geoms
    np.testing.assert_allclose(slippery.model.geom_friction[geoms, 0], 0.5 * nominal.model.geom_friction[geoms, 0])


def test_friction_perturbation_reaches_the_feet(make_world):
    """A foot-floor contact (equal priorities) takes the larger of the two geoms' friction: scaling the floor
    alone left the feet's friction where it was."""
    nominal, slippery = make_world(), make_world(ALL["friction_x0.5"])
    m = nominal.model
    floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    feet = [g for g in range(m.ngeom) if "ankle_roll" in (m.body(m.geom_bodyid[g]).name or "")]
    assert feet and (m.geom_priority[feet] == m.geom_priority[floor]).all()

    def contact(world):
        f = world.model.geom_friction[:, 0]
        return np.maximum(f[feet], f[floor])

    np.testing.assert_allclose(contact(slippery), 0.5 * contact(nominal))


def test_pushes_after_release(make_world, contract):
    world = make_world(replace(NOMINAL, push_dv=0.5, push_interval_s=(0.2, 0.2)))
    _command(world, contract)
    world.advance_to(0.5)
    assert world.pushes == []  # never while in the gantry
    world.release_gantry()
    world.advance_to(0.75)
    assert len(world.pushes) == 1
    t, dv = world.pushes[0]
    assert t == pytest.approx(0.7, abs=world.pd_dt) and np.linalg.norm(dv) == pytest.approx(0.5)
    assert np.linalg.norm(world.data.xfrc_applied[world.layout.pelvis, :3]) > 0  # still pushing (0.1 s)
    world.advance_to(0.85)
    assert np.all(world.data.xfrc_applied[world.layout.pelvis, :3] == 0)
