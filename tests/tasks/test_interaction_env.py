"""The interaction environment composes its terms correctly on a small hand-built reference."""

import pytest
import torch

from robot_hoi.data.objects import box_asset
from robot_hoi.embodiment import load_embodiment
from robot_hoi.tasks.interaction.env import InteractionEnv
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
from robot_hoi.tasks.interaction.reference import ReferenceMotion, nearest_surface_vectors
from robot_hoi.tasks.interaction.scene_setup import InteractionScene
from robot_hoi.utils.torch_rot import quat_apply

FRAMES = 40


@pytest.fixture(scope="module")
def scene():
    return InteractionScene(load_embodiment("g1_inspire"), box_asset((0.4, 0.4, 0.3)))


def standing_reference(scene: InteractionScene, frames: int = FRAMES) -> ReferenceMotion:
    """The robot standing still, a box resting 0.6 m in front: every reference quantity from the model's FK."""
    lay = scene.layout
    robot_qpos = scene.default_robot_qpos()
    obj = torch.tensor([[0.6, 0.0, 0.15, 1.0, 0.0, 0.0, 0.0]])
    backend = scene.make_backend(1, nthread=1)
    backend.set_state(torch.arange(1), torch.cat([robot_qpos, obj], 1).double(),
                      torch.zeros(1, scene.model.nv, dtype=torch.float64))
    sens = backend.sensordata.float()
    link_pos = sens[:, lay.link_pos].reshape(1, -1, 3).repeat(frames, 1, 1)
    link_quat = sens[:, lay.link_quat].reshape(1, -1, 4).repeat(frames, 1, 1)
    points = torch.as_tensor(scene.object_asset.sample_points, dtype=torch.float32)
    points_world = quat_apply(obj[:, None, 3:7], points[None]) + obj[:, None, :3]
    return ReferenceMotion(
        fps=30.0, link_pos=link_pos, link_quat_wxyz=link_quat,
        robot_qpos=robot_qpos.repeat(frames, 1), robot_qvel=torch.zeros(frames, lay.robot_nv),
        joint_pos=torch.as_tensor(scene.embodiment.default_pos, dtype=torch.float32).repeat(frames, 1),
        object_pos=obj[:, :3].repeat(frames, 1), object_quat_wxyz=obj[:, 3:].repeat(frames, 1),
        object_lin_vel=torch.zeros(frames, 3), object_ang_vel=torch.zeros(frames, 3),
        hand_contact=torch.zeros(frames, 2, dtype=torch.bool), object_points=points,
        d_hat=nearest_surface_vectors(link_pos, points_world.repeat(frames, 1, 1)), name="stand",
    )


def make_env(scene, **overrides) -> InteractionEnv:
    cfg = InteractionEnvCfg(num_envs=8, nthread=2, seed=3)
    cfg.init.joint_noise = 0.0
    for key, value in overrides.items():
        setattr(cfg, key, value)
    return InteractionEnv(cfg, scene, [standing_reference(scene)])


def test_step_shapes_rewards_and_logs(scene):
    env = make_env(scene)
    obs = env.reset()
    assert set(obs) == {"policy", "critic"}
    assert obs["policy"].shape == (8, env.obs_dims["policy"])
    assert env.obs_dims["critic"] > env.obs_dims["policy"]
    hold = torch.zeros(8, env.num_actions)  # zero action = default pose targets
    for _ in range(5):
        obs, reward, terminated, truncated, extras = env.step(hold)
        assert torch.isfinite(obs["policy"]).all()
        assert ((reward > 0) & (reward <= 1)).all()
    # a standing robot tracking a standing reference is rewarded highly on position
    assert env.w_d.sum(-1).allclose(torch.ones(8), atol=1e-5)
    pos_reward = torch.exp(-30.0 * env.reward_funcs["link_pos"][0](env))
    assert pos_reward.mean() > 0.5


def test_warmup_holds_the_reference_clock(scene):
    env = make_env(scene)
    env.cfg.init.stand_start_probability = 1.0
    env.reset()
    assert (env.warmup_left == env.cfg.warmup_frames).all()
    start = env.ref_index.clone()
    for _ in range(env.cfg.warmup_frames):
        env.step(torch.zeros(8, env.num_actions))
    assert torch.equal(env.ref_index, start)  # clock held during the 15 warmup frames
    env.step(torch.zeros(8, env.num_actions))
    assert torch.equal(env.ref_index, start + 1)  # then tracking begins



def test_warmup_blend_matches_the_deploy_runtime(scene):
    """With warmup_blend the env's PD offset over a stand start is, tick for tick, what the deploy runtime sends
    (deploy.contract.reference_offset): one definition of the warmup, so sim2sim and the robot see the training's."""
    import dataclasses

    import numpy as np

    from deploy.contract import ReferenceInfo
    from deploy.devpolicy import make_contract
    from deploy.embodiment import load_embodiment as load_deploy_embodiment

    env = make_env(scene)
    env.ref_joint_pos += 0.2  # a frame 0 away from the stand (this scene's reference stands)
    env.cfg.warmup_blend = True
    env.cfg.init.stand_start_probability = 1.0
    env.cfg.init.spawn_noise_xy = 0.0
    env.reset()
    contract = dataclasses.replace(make_contract(load_deploy_embodiment("g1_inspire"),
                                                 reference=ReferenceInfo("x.motion.npz", "0" * 64)),
                                   action_offset_mode="reference", warmup_frames=env.cfg.warmup_frames,
                                   warmup_blend=True)
    np.testing.assert_allclose(contract.default_pose, env.default_joint_pos.numpy(), atol=1e-6)
    clip = int(env.clip_id[0])
    joint_pos = env.ref_joint_pos[env.clip_start[clip]:env.clip_end[clip] + 1].numpy().astype(np.float64)
    assert np.abs(env.action_offset()[0].numpy() - joint_pos[0]).max() > 0.1  # the blend starts at the stand
    for tick in range(env.cfg.warmup_frames + 3):
        np.testing.assert_allclose(env.action_offset()[0].numpy(), contract.reference_offset(tick, joint_pos),
                                   atol=1e-5, err_msg=f"tick {tick}")
        env.step(torch.zeros(8, env.num_actions))
    env.cfg.warmup_blend = False  # the step: frame 0's joints from the first tick
    env.reset()
    np.testing.assert_allclose(env.action_offset()[0].numpy(), joint_pos[0], atol=1e-6)

def test_command_rate_limit_shapes_targets_as_the_deploy_runtime(scene):
    """With command_rate_limit the PD targets start from the measured joints at a reset and move at most limit x dt
    a step, tick for tick what deploy.safety.TargetShaper sends for the same targets; off, they jump."""
    import numpy as np

    from deploy.devpolicy import make_contract
    from deploy.embodiment import load_embodiment as load_deploy_embodiment
    from deploy.safety import TargetShaper

    env = make_env(scene, command_rate_limit=3.0)
    env.reset()
    contract = make_contract(load_deploy_embodiment("g1_inspire"))
    shaper = TargetShaper(contract, env.dt, 3.0)
    shaper.reset(env.joint_pos[0].numpy().astype(np.float64))
    assert torch.equal(env.last_ctrl, env.joint_pos)
    push = torch.full((8, env.num_actions), env.cfg.action_clip)
    for _ in range(3):
        before = env.last_ctrl.clone()
        target = torch.minimum(env.action_offset() + env.action_scale * push, env.ctrl_high)
        env.step(push)
        assert (env.last_ctrl - before).abs().max() <= 3.0 * env.dt + 1e-6
        np.testing.assert_allclose(env.last_ctrl[0].numpy(), shaper(target[0].numpy().astype(np.float64)), atol=1e-5)
    free = make_env(scene)
    free.reset()
    free.step(push)
    assert (free.last_ctrl - free.joint_pos).abs().max() > 10 * 3.0 * free.dt  # no limit: the targets jump


def test_clip_end_truncates_with_success(scene):
    env = make_env(scene)
    env.cfg.init.stand_start_probability = 0.0
    env.cfg.init.start_range = (0.0, 0.0)  # from the clip's start: reaching its end covers it (a success)
    env.psi.cfg.enabled = False
    env.reset()
    saw_success = False
    for _ in range(FRAMES + 2):
        _, _, terminated, truncated, extras = env.step(torch.zeros(8, env.num_actions))
        if truncated.any():
            assert "final_obs" in extras
            saw_success |= extras["log"]["Metrics/success"] > 0
    assert saw_success


def test_falling_robot_terminates(scene):
    env = make_env(scene)
    env.reset()
    # push the pelvis target far away from the reference: a large link error must end the episode
    env.ref_link_pos += torch.tensor([0.0, 0.0, 1.0])
    _, _, terminated, _, _ = env.step(torch.zeros(8, env.num_actions))
    assert terminated.all()


def test_object_mass_randomisation_draws_per_episode_masses_the_physics_uses(scene):
    from robot_hoi.errors import UserError
    from robot_hoi.tasks.interaction.env_cfg import RandomizationCfg

    base = scene.object_mass
    body = scene.object_body_id()
    env = make_env(scene)
    assert torch.equal(env.object_mass, torch.full((8,), base))  # off by default: the clip's mass
    env = make_env(scene, randomization=RandomizationCfg(object_mass_scale=(0.5, 2.0)))
    levels = env.object_mass_levels / base  # a 2 % geometric grid from x0.5 to x2: few distinct physics models
    assert levels[0] == pytest.approx(0.5) and levels[-1] == pytest.approx(2.0) and 65 <= len(levels) <= 73
    assert torch.allclose(levels[2:-1] / levels[1:-2], torch.tensor(1.02), atol=1e-5)
    masses = env.object_mass / base
    assert masses.unique().numel() > 3 and all(torch.isclose(levels, m).any() for m in masses)
    # the physics steps each env with its drawn mass
    models = env.backend._models
    assert [float(m.body_mass[body]) for m in models] == pytest.approx(env.object_mass.tolist(), rel=1e-6)
    env.step(torch.zeros(8, env.num_actions))
    # an eval at one fixed scale
    env = make_env(scene, randomization=RandomizationCfg(object_mass_scale=(2.0, 2.0)))
    assert torch.allclose(env.object_mass, torch.full((8,), 2 * base))
    assert [float(m.body_mass[body]) for m in env.backend._models] == pytest.approx([2 * base] * 8)
    with pytest.raises(UserError, match="object_mass_scale"):
        make_env(scene, randomization=RandomizationCfg(object_mass_scale=(2.0, 1.0)))
