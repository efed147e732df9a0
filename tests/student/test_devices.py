"""The student's per-step parts stay on the env's device without host syncs: run on torch's `meta` device, where
any host read raises and a CPU tensor mixed in raises as it would on CUDA. Host-side samplers hand their plans
over on the env's device."""

from __future__ import annotations

from types import SimpleNamespace

import torch

from robot_hoi.data.objects import box_asset
from robot_hoi.rl.config import ActorCriticConfig
from robot_hoi.rl.models import ActorCritic
from robot_hoi.student.height_map import HeightMap
from robot_hoi.student.history import HistoryEncoder, HistoryProvider
from robot_hoi.student.samplers import StartSampler
from robot_hoi.student.student_env import StudentEnv
from robot_hoi.student.teachers import CompositeTeacher, TeacherMember

META = torch.device("meta")
N, OBS, ACT = 6, 5, 3


def _meta(*shape, dtype=torch.float32):
    return torch.zeros(*shape, dtype=dtype, device=META)


class _MetaEnv:
    """The parts of an InteractionEnv the student's step path reads, on the meta device."""

    def __init__(self) -> None:
        self.num_envs, self.num_actions, self.device = N, ACT, META
        self.max_episode_length, self.obs_dims = 10, {"policy": OBS, "student": OBS}
        self.start_sampler = None
        self.clip_id = _meta(N, dtype=torch.long)
        self.action_scale = torch.ones(ACT, device=META)
        self.root_pos, self.object_pos = _meta(N, 3), _meta(N, 3)
        self.root_quat = self.object_quat = torch.tensor([1.0, 0, 0, 0], device=META).expand(N, 4)

    def action_offset(self) -> torch.Tensor:
        return _meta(N, ACT)

    def step(self, actions):
        done = _meta(N, dtype=torch.bool)
        return {"policy": _meta(N, OBS), "student": _meta(N, OBS)}, _meta(N), done, done, {}


def test_one_teacher_answers_every_row_on_the_env_device_without_sync():
    env = _MetaEnv()
    model = ActorCritic(OBS, OBS, ACT, ActorCriticConfig(actor_hidden_dims=[8], critic_hidden_dims=[8])).to(META)
    member = TeacherMember("t", model, checkpoint=None, action_offset="default")
    member.view = SimpleNamespace(teacher_observation=lambda: _meta(N, OBS), action_offset=lambda mode: _meta(N, ACT))
    mean, std, which = CompositeTeacher([member], [0]).act(env)
    assert mean.shape == (N, ACT) and std.shape == (N, ACT) and mean.device == std.device == which.device == META


def test_student_env_steps_with_history_and_height_map_providers_on_the_env_device():
    env = _MetaEnv()
    encoder = HistoryEncoder(num_features=2, length=4, dim=3)
    providers = {"history": HistoryProvider(encoder, torch.tensor([0, 2]), N),
                 "height_map": HeightMap(box_asset((0.4, 0.4, 0.3)), size=3)}
    wrapped = StudentEnv(env, providers)
    obs, reward, *_ = wrapped.step(_meta(N, ACT))
    assert obs["history"].shape == (N, 3) and obs["height_map"].shape == (N, 9)
    assert obs["history"].device == obs["height_map"].device == reward.device == META


def test_start_sampler_draws_on_the_host_and_hands_the_plan_to_the_env_device():
    env = SimpleNamespace(device=META)
    sampler = StartSampler(N, num_clips=3, generator=torch.Generator().manual_seed(0))
    plan = sampler.plan(env, torch.arange(2, 5))
    assert plan.clip.device == plan.custom.device == META and plan.clip.shape == (3,)
    assert sampler.records["custom"].device.type == "cpu"
