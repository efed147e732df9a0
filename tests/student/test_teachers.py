"""The composite teacher: observations against the teacher's own reference, routing by clip, and actions
re-expressed in the student env's action parametrisation."""

import torch

from robot_hoi.student.reference_view import ReferenceTimeline, ReferenceView
from robot_hoi.student.teachers import CompositeTeacher, TeacherMember

from .conftest import make_env, make_reference


def test_view_on_the_env_reference_reproduces_the_policy_group(scene):
    env = make_env(scene, [make_reference(scene, drift=0.01)])
    for _ in range(3):
        obs, *_ = env.step(0.2 * torch.randn(env.num_envs, env.num_actions))
    view = ReferenceView(env, ReferenceTimeline(env.references, env), env.cfg.keyframes,
                         env.cfg.warmup_frames)
    assert torch.equal(view.teacher_observation(), obs["policy"])
    assert torch.equal(view.action_offset("reference"), env.action_offset())


def twin_on(scene, env, reference):
    """An env on `reference` in exactly `env`'s simulated and episode state (the state set in both, so their
    sensors are computed from it alike)."""
    twin = make_env(scene, [reference], num_envs=env.num_envs, warmup_frames=env.cfg.warmup_frames)
    qpos, qvel = env.backend.qpos.clone(), env.backend.qvel.clone()
    for e in (env, twin):
        e.backend.set_state(torch.arange(env.num_envs), qpos, qvel)
    for name in ("ref_index", "clip_id", "warmup_left", "warmup_length", "warmup_start_pos", "episode_length",
                 "tracked_steps", "last_actions"):
        setattr(twin, name, getattr(env, name).clone())
    env._update_state()
    twin._update_state()
    return twin


def test_view_reads_another_reference_as_an_env_built_on_it_would(scene):
    student_ref = make_reference(scene, drift=0.01)
    teacher_ref = make_reference(scene, drift=0.01, offset_x=0.05)  # the MoCap the teacher was trained on
    env = make_env(scene, [student_ref])
    for _ in range(4):
        env.step(0.2 * torch.randn(env.num_envs, env.num_actions))
    view = ReferenceView(env, ReferenceTimeline([teacher_ref], env), env.cfg.keyframes,
                         env.cfg.warmup_frames)
    twin = twin_on(scene, env, teacher_ref)
    env.last_actions = twin.last_actions = torch.zeros_like(env.last_actions)  # compared on their own below
    expected = twin._observations()["policy"]
    assert torch.allclose(view.teacher_observation(), expected, atol=1e-6)
    assert not torch.allclose(env._observations()["policy"], expected, atol=1e-3)


def test_a_teacher_acting_through_the_view_sees_and_does_what_it_would_in_its_own_env(scene):
    """Through the warmup and after it: the same PD targets, and a last-action observation in the teacher's own
    parametrisation (its joints sit 0.1 rad off the student env's reference)."""
    student_ref = make_reference(scene)
    teacher_ref = make_reference(scene, offset_x=0.05)
    teacher_ref.joint_pos = teacher_ref.joint_pos + 0.1
    env = make_env(scene, [student_ref], warmup_frames=5)
    env.cfg.init.stand_start_probability = 1.0
    env.reset()
    view = ReferenceView(env, ReferenceTimeline([teacher_ref], env), env.cfg.keyframes, env.cfg.warmup_frames)
    twin = twin_on(scene, env, teacher_ref)
    torch.manual_seed(0)
    shifted = 0
    for step in range(8):
        assert torch.allclose(view.action_offset("reference"), twin.action_offset(), atol=1e-6), step
        teacher_action = 0.3 * torch.randn(env.num_envs, env.num_actions)
        student_action = teacher_action + (view.action_offset("reference") - env.action_offset()) / env.action_scale
        twin.step(teacher_action)
        env.step(student_action)
        assert int(env.episode_length.min()) == step + 1  # no reset in either
        assert torch.allclose(view.last_actions, twin.last_actions, atol=1e-5), step
        assert torch.allclose(view.teacher_observation(), twin._observations()["policy"], atol=1e-4), step
        shifted += not torch.allclose(env.last_actions, twin.last_actions, atol=1e-3)
    assert shifted == 8  # read raw, the env's last action is not the teacher's


class ConstantPolicy(torch.nn.Module):
    def __init__(self, value: float, num_actions: int, std: float = 0.3):
        super().__init__()
        self.value, self.num_actions = value, num_actions
        self.action_std = torch.full((num_actions,), std)

    def act_inference(self, obs):
        return torch.full((obs.shape[0], self.num_actions), self.value)


def test_routing_by_clip_and_action_reparametrisation(scene):
    # student clips are "distilled" (shifted joints); the teachers act around their own (MoCap) references
    distilled = [make_reference(scene, name="a"), make_reference(scene, name="b")]
    mocap = [make_reference(scene, name="a"), make_reference(scene, name="b")]
    for ref in mocap:
        ref.joint_pos = ref.joint_pos + 0.1
    env = make_env(scene, distilled, num_envs=6)
    env.clip_id[:] = torch.tensor([0, 1, 0, 1, 1, 0])
    view = ReferenceView(env, ReferenceTimeline(mocap, env), env.cfg.keyframes,
                         env.cfg.warmup_frames)
    members = [TeacherMember("t0", ConstantPolicy(0.5, env.num_actions), None, view=view, action_offset="reference"),
               TeacherMember("t1", ConstantPolicy(-0.5, env.num_actions, 0.1), None, view=view,
                             action_offset="default")]
    composite = CompositeTeacher(members, [0, 1])
    mean, std, which = composite.act(env)
    assert which.tolist() == [0, 1, 0, 1, 1, 0]
    scale = env.action_scale
    # the PD target each teacher meant is what the student env reaches with the returned action
    reached = env.action_offset() + scale * mean
    mocap_next = view.action_offset("reference")
    rows0, rows1 = which == 0, which == 1
    assert torch.allclose(reached[rows0], (mocap_next + scale * 0.5)[rows0], atol=1e-6)
    assert torch.allclose(reached[rows1], (env.default_joint_pos - scale * 0.5).expand(6, -1)[rows1], atol=1e-6)
    # teacher 0's joints sit 0.1 rad above the distilled ones: its action shifts by 0.1 / scale
    assert torch.allclose(mean[rows0], (0.5 + 0.1 / scale).expand(3, -1), atol=1e-5)
    assert torch.equal(std[rows0], torch.full((3, env.num_actions), 0.3))
    assert torch.equal(std[rows1], torch.full((3, env.num_actions), 0.1))
