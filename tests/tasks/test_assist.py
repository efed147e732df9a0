"""Assist wrenches (curriculum), the compact teacher observation and the hold test, on small CPU envs."""

from __future__ import annotations

import pytest
import torch

from robot_hoi.data.objects import box_asset
from robot_hoi.embodiment import load_embodiment
from robot_hoi.tasks.interaction.env import InteractionEnv
from robot_hoi.tasks.interaction.env_cfg import AssistCfg, InteractionEnvCfg
from robot_hoi.tasks.interaction.mdp.assist import assist_level, pd_wrench
from robot_hoi.tasks.interaction.scene_setup import InteractionScene
from robot_hoi.utils.torch_rot import quat_from_yaw, quat_to_rotvec

from .test_interaction_env import standing_reference


@pytest.fixture(scope="module")
def scene():
    return InteractionScene(load_embodiment("g1_inspire"), box_asset((0.4, 0.4, 0.3), mass_kg=2.0))


def _env(scene, **assist) -> InteractionEnv:
    cfg = InteractionEnvCfg(num_envs=2, nthread=1, seed=3, backend="cpu")
    cfg.init.joint_noise = 0.0
    cfg.init.stand_start_probability = 0.0
    cfg.init.start_range = (0.0, 0.0)
    cfg.psi.enabled = False
    cfg.assist = AssistCfg(**assist)
    return InteractionEnv(cfg, scene, [standing_reference(scene)])


def test_schedule_anneals_linearly_to_zero_and_is_off_when_disabled():
    cfg = AssistCfg(enabled=True, initial_level=0.8, anneal_samples=1000)
    assert [assist_level(cfg, n) for n in (0, 500, 1000, 5000)] == pytest.approx([0.8, 0.4, 0.0, 0.0])
    assert assist_level(AssistCfg(enabled=False), 0) == 0.0


def test_pd_wrench_by_hand():
    zero = torch.zeros(1, 3)
    identity = torch.tensor([[1.0, 0.0, 0.0, 0.0]])
    turned = quat_from_yaw(torch.tensor([0.3]))
    w = pd_wrench(zero, identity, torch.tensor([[0.0, 0.0, 1.0]]), zero, torch.tensor([[0.1, 0.0, 0.0]]), turned,
                  zero, zero, kp=100.0, kd=10.0, kp_rot=5.0, kd_rot=1.0)
    torch.testing.assert_close(w[0, :3], torch.tensor([10.0, 0.0, -10.0]))  # kp * 0.1 m; kd * -1 m/s
    torch.testing.assert_close(w[0, 3:], torch.tensor([0.0, 0.0, 1.5]))    # kp_rot * 0.3 rad about z
    torch.testing.assert_close(quat_to_rotvec(turned), torch.tensor([[0.0, 0.0, 0.3]]))


def test_object_assist_carries_the_object_toward_its_reference(scene):
    """A box lifted 20 cm above its reference height falls without the assist; with it the PD wrench (and its
    share of the weight) holds it near the reference. The same env with the curriculum off has no wrench at all."""
    heights = {}
    for name, level in (("off", 0.0), ("on", 1.0)):
        env = _env(scene, enabled=True, object_kp=400.0, object_kd=40.0, object_gravity_share=1.0,
                   assisted_share=1.0)
        env.reset()
        qpos, qvel = env.backend.qpos.clone(), env.backend.qvel.clone()
        qpos[:, env.layout.object_qpos + 2] += 0.2
        env.backend.set_state(torch.arange(2), qpos, qvel)
        env.assist_level = level
        for _ in range(20):
            env.step(torch.zeros(2, env.num_actions))
        heights[name] = float(env.object_pos[0, 2])
    reference = 0.15
    assert heights["off"] == pytest.approx(reference, abs=0.01)            # it fell back onto the floor
    assert abs(heights["on"] - reference) < abs(heights["off"] - reference) + 0.05
    assert heights["on"] == pytest.approx(reference, abs=0.03)


def test_curriculum_logged_and_checkpointed(scene):
    env = _env(scene, enabled=True, anneal_samples=100)
    assert env.update_curriculum(50) == {"Curriculum/assist_level": pytest.approx(0.5),
                                         "Curriculum/object_termination_m": env.cfg.terminations.max_mean_object_point_error}
    assert env.curriculum_state() == {"assist_level": pytest.approx(0.5)}
    env.update_curriculum(200)
    assert env.assist_level == 0.0


def test_object_line_widens_with_the_level_and_tightens_as_it_anneals(scene):
    """A box 20 cm above its reference ends the episode at the evaluated 12 cm line; with a 0.3 m margin at full
    level it does not, at half level (0.27 m) neither, and once the assist has faded it does again."""
    env = _env(scene, enabled=True, anneal_samples=100, object_termination_margin=0.3)
    env.cfg.terminations.max_mean_object_point_error = 0.12

    def object_deviation_after_lift(total_samples: int) -> bool:
        env.update_curriculum(total_samples)
        env.reset()
        qpos, qvel = env.backend.qpos.clone(), env.backend.qvel.clone()
        qpos[:, env.layout.object_qpos + 2] += 0.2
        env.backend.set_state(torch.arange(2), qpos, qvel)
        env._update_state()
        return bool(env._terminations()["object_deviation"].all())

    assert not object_deviation_after_lift(0)
    assert env.update_curriculum(50)["Curriculum/object_termination_m"] == pytest.approx(0.27)
    assert not object_deviation_after_lift(50)
    assert object_deviation_after_lift(100)
    assert object_deviation_after_lift(0) is False  # widened again at full level: derived from it, not stored
    assert env.cfg.terminations.max_mean_object_point_error == 0.12


def test_evaluation_never_assists():
    from robot_hoi.rl.evaluation import evaluation_settings

    cfg = InteractionEnvCfg()
    cfg.assist.enabled = True
    evaluation_settings(cfg, 4, 0)
    assert not cfg.assist.enabled and assist_level(cfg.assist, 0) == 0.0


def test_evaluation_uses_the_clips_object_unless_set_otherwise():
    from robot_hoi.rl.evaluation import apply_env_overrides, evaluation_settings

    cfg = InteractionEnvCfg()
    cfg.randomization.object_mass_scale = (0.5, 2.0)  # as trained
    evaluation_settings(cfg, 4, 0)
    assert cfg.randomization.object_mass_scale == (1.0, 1.0)
    cfg = apply_env_overrides(cfg, ["env.randomization.object_mass_scale=[2, 2]"])  # `robot-hoi eval --set`
    assert tuple(cfg.randomization.object_mass_scale) == (2.0, 2.0)


def test_compact_observation_is_small_and_matches_its_spec(scene):
    from robot_hoi.tasks.interaction.mdp.observations import teacher_observation_spec

    env = _env(scene)
    compact = env.obs_dims["policy"]
    assert compact == sum(t["size"] for t in teacher_observation_spec(env))
    env.cfg.teacher_obs = "full"
    full = env._observations()["policy"].shape[1]
    assert compact < full / 3
    env.cfg.teacher_obs = "nope"
    with pytest.raises(ValueError, match="teacher_obs"):
        env._observations()


def test_failure_weighted_starts_follow_the_terminations(scene):
    """Starts concentrate on the clip segment where episodes ended; without the option they stay uniform."""
    env = _env(scene)
    env.cfg.init.failure_weighted = True
    env.cfg.init.start_range = (0.0, 1.0)
    terminated = torch.ones(2, dtype=torch.bool)
    env.ref_index[:] = env.clip_start[0] + 30  # frame 30 of 40: segment 15 of 20
    for _ in range(50):
        env._count_failures(terminated)
    assert env.failure_counts[0, 15] == 100 and env.failure_counts.sum() == 100
    frames = env._random_frames(torch.zeros(4000, dtype=torch.long))
    share = ((frames >= 29) & (frames <= 31)).float().mean().item()
    assert share > 0.5  # 101 / 120 of the weight sits on that segment (uniform would give ~0.07)
    env.cfg.init.failure_weighted = False
    frames = env._random_frames(torch.zeros(4000, dtype=torch.long))
    assert ((frames >= 29) & (frames <= 31)).float().mean().item() < 0.15


def test_failure_counts_fade_with_their_half_life_when_asked(scene):
    env = _env(scene)
    terminated = torch.ones(2, dtype=torch.bool)
    fade = 0.5 ** (2 / 20)  # per step of 2 samples, at a half-life of 20 samples
    faded = 2 * (1 - fade ** 50) / (1 - fade) * fade ** 50  # counted over 50 steps, then faded over 50 more
    for half_life, early_left in ((0.0, 100.0), (20.0, faded)):
        env.cfg.init.failure_half_life_samples = half_life
        env.failure_counts.zero_()
        env.ref_index[:] = env.clip_start[0] + 30  # segment 15: where episodes used to end
        for _ in range(50):
            env._count_failures(terminated)
        env.ref_index[:] = env.clip_start[0] + 10  # segment 5: where they end now, for 50 steps of 2 samples
        for _ in range(50):
            env._count_failures(terminated)
        assert env.failure_counts[0, 15].item() == pytest.approx(early_left, rel=1e-4)
    assert env.failure_counts[0, 5] > 10 * env.failure_counts[0, 15]


def test_only_the_episodes_drawn_to_be_assisted_get_wrenches(scene):
    from robot_hoi.tasks.interaction.mdp.assist import assist_wrench

    env = _env(scene, enabled=True, assisted_share=0.5)
    env.cfg.num_envs = env.num_envs
    env.reset()
    env.assisted[:] = torch.tensor([1.0, 0.0])
    qpos = env.backend.qpos.clone()
    qpos[:, env.layout.object_qpos + 2] += 0.2
    env.backend.set_state(torch.arange(2), qpos, env.backend.qvel.clone())
    env._update_state()
    wrench = assist_wrench(env, 1.0)
    assert wrench[0].abs().sum() > 0 and wrench[1].abs().sum() == 0
    draws = []
    for _ in range(20):
        env._reset_envs(torch.arange(2))
        draws.append(env.assisted.clone())
    share = torch.stack(draws).mean().item()
    assert 0.2 < share < 0.8

