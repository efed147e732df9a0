"""Reference starts inside a hold: the grasp squeeze lives in the PD targets, not in the reference state, so without
the grip settle the hands slam shut and the held box shoots off (measured on lift_carry: reference starts in the carry
survived 0.38 s); with it the box stays put while the grasp loads. Stand starts never settle."""

import pytest
import torch


def _env(settle_frames: int, stand: float):
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.paths import TASK_CONFIG
    from robot_hoi.tasks.interaction import factory
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
    from robot_hoi.utils.config import load_yaml_dataclass

    cfg = load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG)
    cfg.num_envs, cfg.nthread, cfg.backend, cfg.seed = 2, 2, "cpu", 0
    cfg.psi.enabled = False
    cfg.assist.enabled = False
    cfg.init.stand_start_probability = stand
    cfg.init.joint_noise = 0.0
    cfg.init.start_range = (0.5, 0.5)  # lift_place: the box held up, both hands on it
    cfg.init.grip_settle_frames = settle_frames
    return factory.make_env([factory.load_source("embedded:lift_place")], cfg, load_embodiment("g1_inspire"))


def _object_error_cm(env, frames: int) -> float:
    for _ in range(frames):
        env.step(torch.zeros(env.num_envs, env.num_actions))
    return 100 * float((env.object_pos - env.ref_object_pos[env.ref_index]).norm(dim=-1).max())


@pytest.mark.parametrize("settle_frames, low, high", [(0, 4.0, 100.0), (20, 0.0, 2.5)])
def test_reference_start_in_a_hold_keeps_the_box_while_the_grasp_loads(settle_frames, low, high):
    env = _env(settle_frames, stand=0.0)
    assert bool(env.hand_contact_found.all())  # started holding the box
    assert (env.grip_settle_left == settle_frames).all()
    assert low < _object_error_cm(env, 10) < high  # 0: 7 cm off after 10 frames (zero action); 20: 1.2 cm


def test_stand_starts_do_not_settle():
    env = _env(20, stand=1.0)
    assert (env.grip_settle_left == 0).all()
