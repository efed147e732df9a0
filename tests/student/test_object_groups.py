"""A student over clips of several objects: one env per object stepped as one batch, each group's teachers
answering for its own rows."""

import pytest
import torch

from robot_hoi.data.objects import box_asset
from robot_hoi.embodiment import load_embodiment
from robot_hoi.errors import UserError
from robot_hoi.student.object_groups import GroupedTeacher, ObjectGroupsEnv, split_envs
from robot_hoi.student.reference_view import ReferenceTimeline, ReferenceView
from robot_hoi.student.teachers import CompositeTeacher, TeacherMember
from robot_hoi.tasks.interaction.scene_setup import InteractionScene

from .conftest import make_env, make_reference
from .test_teachers import ConstantPolicy


@pytest.fixture(scope="module")
def tall_scene() -> InteractionScene:
    return InteractionScene(load_embodiment("g1_inspire"), box_asset((0.3, 0.3, 0.7)))


def test_envs_are_shared_in_proportion_to_clips_with_one_per_object():
    assert split_envs(64, [1, 10]) == [6, 58]
    assert split_envs(5, [1, 100]) == [1, 4]
    assert split_envs(3, [1, 1, 1]) == [1, 1, 1]
    assert sum(split_envs(7, [2, 3, 5])) == 7
    with pytest.raises(UserError, match="at least one env per object"):
        split_envs(2, [1, 1, 1])


def groups(scene, tall_scene, frames=40):
    """Two clips on the box (3 envs), one on the tall box (2 envs); references short enough to end episodes."""
    return [make_env(scene, [make_reference(scene, frames, name="a"), make_reference(scene, frames, name="b")],
                     num_envs=3),
            make_env(tall_scene, [make_reference(tall_scene, frames, name="c")], num_envs=2)]


def test_groups_step_as_one_batch_with_clips_numbered_over_all_groups(scene, tall_scene):
    env = ObjectGroupsEnv(groups(scene, tall_scene, frames=6))
    twins = groups(scene, tall_scene, frames=6)  # the same envs stepped apart
    assert env.num_envs == 5 and [r.name for r in env.references] == ["a", "b", "c"]
    obs = env.reset()
    apart = [t.reset() for t in twins]
    assert obs["student"].shape[0] == 5
    assert torch.equal(obs["policy"], torch.cat([o["policy"] for o in apart]))
    assert set(env.clip_id[:3].tolist()) <= {0, 1} and env.clip_id[3:].tolist() == [2, 2]
    ended_clips, final_seen = [], False
    for _ in range(30):
        actions = 0.1 * torch.randn(5, env.num_actions)
        obs, reward, terminated, truncated, extras = env.step(actions)
        steps = [twins[0].step(actions[:3]), twins[1].step(actions[3:])]
        assert torch.equal(obs["policy"], torch.cat([s[0]["policy"] for s in steps]))
        assert torch.equal(reward, torch.cat([s[1] for s in steps]))
        done = terminated | truncated
        ended_clips += extras["episode"]["clip_id"].long().tolist()
        assert len(extras["episode"]["success"]) == int(done.sum())
        if "final_obs" in extras:
            final_seen = True
            assert extras["final_obs"]["critic"].shape == obs["critic"].shape
    assert final_seen and 2 in ended_clips and set(ended_clips) <= {0, 1, 2}


def test_groups_must_share_the_observation_layout(scene, tall_scene):
    box, tall = groups(scene, tall_scene)
    tall.obs_dims = dict(tall.obs_dims, student=tall.obs_dims["student"] + 1)
    with pytest.raises(UserError, match="disagree on the observation layout"):
        ObjectGroupsEnv([box, tall])


def test_each_group_is_answered_by_its_own_teachers(scene, tall_scene):
    envs = groups(scene, tall_scene)
    composites = []
    for k, env in enumerate(envs):
        view = ReferenceView(env, ReferenceTimeline(env.references, env), env.cfg.keyframes, env.cfg.warmup_frames)
        member = TeacherMember(f"t{k}", ConstantPolicy(0.5 - k, env.num_actions, 0.1 + k), None, view=view)
        composites.append(CompositeTeacher([member], [0] * len(env.references)))
    env = ObjectGroupsEnv(envs)
    env.reset()
    mean, std, which = GroupedTeacher(composites).act(env)
    assert which.tolist() == [0, 0, 0, 1, 1]
    assert torch.allclose(mean[:3], torch.full((3, env.num_actions), 0.5), atol=1e-5)
    assert torch.allclose(mean[3:], torch.full((2, env.num_actions), -0.5), atol=1e-5)
    assert torch.allclose(std[3:], torch.full((2, env.num_actions), 1.1))
