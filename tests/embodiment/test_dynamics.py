"""Short simulations of the generated model: hands, mimic couplings, standing, batched rollout."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from robot_hoi.embodiment import build_model, load_embodiment


@pytest.fixture(scope="module")
def cfg():
    return load_embodiment("g1_inspire")


@pytest.fixture(scope="module")
def hand_model(cfg):
    return build_model(cfg, fixed_base=True, floor=False)


def _hand_actuators(model):
    return [i for i in range(model.nu) if model.actuator(i).name[:2] in ("L_", "R_")]


def _qpos_of_actuator(model, data, i):
    return data.qpos[model.jnt_qposadr[model.actuator_trnid[i, 0]]]


def _mimic_errors(model, data) -> np.ndarray:
    passive = data.qpos[model.jnt_qposadr[model.eq_obj1id]]
    driver = data.qpos[model.jnt_qposadr[model.eq_obj2id]]
    return np.abs(passive - (model.eq_data[:, 0] + model.eq_data[:, 1] * driver))


def test_mimic_couplings_hold_with_random_finger_targets(cfg, hand_model):
    model = hand_model
    rng = np.random.default_rng(7)
    hand = _hand_actuators(model)
    for trial in range(3):
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, 0)
        lo, hi = model.actuator_ctrlrange[hand].T
        data.ctrl[hand] = rng.uniform(lo, hi)
        mujoco.mj_step(model, data, nstep=int(round(2.0 / model.opt.timestep)))
        assert np.isfinite(data.qpos).all()
        assert _mimic_errors(model, data).max() < 0.01, f"trial {trial}: {_mimic_errors(model, data)}"
        reached = np.array([_qpos_of_actuator(model, data, i) for i in hand])
        np.testing.assert_allclose(reached, data.ctrl[hand], atol=0.02)


def test_fingers_close_fully_in_well_under_a_second_without_overshoot(cfg, hand_model):
    model = hand_model
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    hand = _hand_actuators(model)
    start = np.array([_qpos_of_actuator(model, data, i) for i in hand])
    target = model.actuator_ctrlrange[hand, 1]  # fully closed / fully rotated
    data.ctrl[hand] = target
    reached_at = np.full(len(hand), np.inf)
    peak = start.copy()
    worst_mimic_after_closing = 0.0
    for _ in range(int(round(1.0 / model.opt.timestep))):
        mujoco.mj_step(model, data)
        q = np.array([_qpos_of_actuator(model, data, i) for i in hand])
        peak = np.maximum(peak, q)
        done = (q - start) >= 0.95 * (target - start)
        reached_at[done & np.isinf(reached_at)] = data.time
        if data.time > 0.7:
            worst_mimic_after_closing = max(worst_mimic_after_closing, _mimic_errors(model, data).max())
    assert reached_at.max() < 0.7, dict(zip([model.actuator(i).name for i in hand], reached_at, strict=True))
    assert reached_at.min() > 0.15, "faster than any Inspire hand (hardware: ~0.6 s full stroke)"
    assert (peak - target).max() < 0.02, "no overshoot past the closed position"
    assert worst_mimic_after_closing < 0.01


def test_stands_on_the_floor_for_five_seconds(cfg):
    model = build_model(cfg)  # the config's own gains (ankle kp 300: see configs/embodiments/g1_inspire.yaml)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    heights, uprights = [], []
    for _ in range(int(round(5.0 / model.opt.timestep))):
        mujoco.mj_step(model, data)
        heights.append(data.qpos[2])
        uprights.append(data.xmat[model.body("pelvis").id][8])  # world z of the pelvis z axis
    heights = np.array(heights)
    assert np.abs(heights - cfg.spawn_height).max() < 0.03
    assert min(uprights) > 0.98
    assert np.linalg.norm(data.qpos[:2]) < 0.05
    assert np.abs(data.qvel).max() < 0.05, "settled"
    feet = {model.geom("left_foot").id, model.geom("right_foot").id}
    assert {g for c in data.contact[: data.ncon] for g in (c.geom1, c.geom2)} - {model.geom("floor").id} <= feet


def test_batched_rollout_runs(cfg):
    from mujoco import rollout

    model = build_model(cfg)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    n_env, n_step = 4, 20
    state = np.zeros((mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS),))
    mujoco.mj_getState(model, data, state, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    ctrl = np.tile(cfg.default_pos, (n_env, n_step, 1))
    states, _ = rollout.rollout(model, mujoco.MjData(model), np.tile(state, (n_env, 1)), ctrl)
    assert states.shape[:2] == (n_env, n_step) and np.isfinite(states).all()
