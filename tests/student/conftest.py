"""Small, fast building blocks for the student tests: a G1 scene with a box, hand-built references from the
model's forward kinematics (a robot standing still; optionally drifting along x), tiny envs and tiny teachers."""

from __future__ import annotations

import pytest
import torch

from robot_hoi.data.objects import box_asset
from robot_hoi.embodiment import load_embodiment
from robot_hoi.rl.config import ActorCriticConfig
from robot_hoi.rl.models import ActorCritic
from robot_hoi.tasks.interaction.env import InteractionEnv
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
from robot_hoi.tasks.interaction.mdp.observations import STUDENT_TERMS
from robot_hoi.tasks.interaction.reference import ReferenceMotion, nearest_surface_vectors
from robot_hoi.tasks.interaction.scene_setup import InteractionScene
from robot_hoi.utils.torch_rot import quat_apply


@pytest.fixture(autouse=True)
def _one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # tiny networks on a shared 2-core machine
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="session")
def scene() -> InteractionScene:
    return InteractionScene(load_embodiment("g1_inspire"), box_asset((0.4, 0.4, 0.3)))


def make_reference(scene: InteractionScene, frames: int = 40, drift: float = 0.0, name: str = "stand",
                   offset_x: float = 0.0) -> ReferenceMotion:
    """The robot standing, a box 0.6 m ahead; robot, links and box move `drift` m per frame along x."""
    lay = scene.layout
    robot_qpos = scene.default_robot_qpos()
    obj = torch.tensor([[0.6, 0.0, 0.15, 1.0, 0.0, 0.0, 0.0]])
    backend = scene.make_backend(1, nthread=1)
    backend.set_state(torch.arange(1), torch.cat([robot_qpos, obj], 1).double(),
                      torch.zeros(1, scene.model.nv, dtype=torch.float64))
    sens = backend.sensordata.float()
    shift = offset_x + drift * torch.arange(frames, dtype=torch.float32)
    dx = torch.stack([shift, torch.zeros(frames), torch.zeros(frames)], dim=-1)  # (T, 3)
    link_pos = sens[:, lay.link_pos].reshape(1, -1, 3) + dx[:, None]
    link_quat = sens[:, lay.link_quat].reshape(1, -1, 4).repeat(frames, 1, 1)
    qpos = robot_qpos.repeat(frames, 1)
    qpos[:, 0] += shift
    object_pos = obj[:, :3] + dx
    points = torch.as_tensor(scene.object_asset.sample_points, dtype=torch.float32)
    points_world = quat_apply(obj[:, None, 3:7], points[None]) + object_pos[:, None, :]
    return ReferenceMotion(
        fps=30.0, link_pos=link_pos, link_quat_wxyz=link_quat, robot_qpos=qpos,
        robot_qvel=torch.zeros(frames, lay.robot_nv),
        joint_pos=torch.as_tensor(scene.embodiment.default_pos, dtype=torch.float32).repeat(frames, 1),
        object_pos=object_pos, object_quat_wxyz=obj[:, 3:].repeat(frames, 1),
        object_lin_vel=torch.zeros(frames, 3), object_ang_vel=torch.zeros(frames, 3),
        hand_contact=torch.zeros(frames, 2, dtype=torch.bool), object_points=points,
        d_hat=nearest_surface_vectors(link_pos, points_world), name=name,
    )


def env_cfg(num_envs: int = 4, **overrides) -> InteractionEnvCfg:
    cfg = InteractionEnvCfg(num_envs=num_envs, nthread=1, seed=3, student_obs_terms=tuple(STUDENT_TERMS))
    cfg.init.joint_noise = 0.0
    cfg.psi.enabled = False
    for key, value in overrides.items():
        setattr(cfg, key, value)
    return cfg


def make_env(scene, references: list[ReferenceMotion], num_envs: int = 4, **overrides) -> InteractionEnv:
    return InteractionEnv(env_cfg(num_envs, **overrides), scene, references)


def tiny_teacher(env, seed: int = 0) -> ActorCritic:
    torch.manual_seed(seed)
    cfg = ActorCriticConfig(actor_hidden_dims=[16], critic_hidden_dims=[16], init_log_std=-1.0)
    return ActorCritic(env.obs_dims["policy"], env.obs_dims["critic"], env.num_actions, cfg).eval()


# ---- a tiny teacher run on the embedded clip, shared by the CLI tests ------------------------------------------------
QUIET = ["--set", "runner.progress=false", "--set", "runner.tensorboard=false", "--set", "env.num_envs=4",
         "--set", "env.nthread=1", "--set", "ppo.horizon=8"]


@pytest.fixture(scope="session")
def teacher_run(tmp_path_factory):
    from robot_hoi.cli import main

    out = tmp_path_factory.mktemp("teachers")
    assert main(["train", "--budget", "2it", "--out", str(out), *QUIET, "--set", "model.actor_hidden_dims=[32]",
                 "--set", "model.critic_hidden_dims=[32]"]) == 0
    return out


def student_args(teachers, out, *extra, budget="2it"):
    """`robot-hoi train student` with a small Transformer; an untrained teacher falls within ~40 frames, so the
    distilled reference may be short."""
    teachers = [str(t) for t in (teachers if isinstance(teachers, list) else [teachers])]
    return ["train", "student", "--teachers", *teachers, "--budget", budget, "--out", str(out), *QUIET,
            "--set", "student.width=32", "--set", "student.heads=2", "--set", "student.feedforward=64",
            "--set", "model.critic_hidden_dims=[32]", "--set", "distill.reference_min_frames=5",
            "--set", "distill.reference_failure_margin=2", "--set", "eval_episodes=1", *extra]
