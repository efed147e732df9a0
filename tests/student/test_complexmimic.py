"""ComplexMimic's mechanics against hand-computed values: difficulty-aware sampling (Eq. 5-9), routing (Eq. 2),
the interaction expert's height map and its warm start from the teacher."""

import math

import pytest
import torch

from robot_hoi.data.objects import box_asset
from robot_hoi.rl.config import ActorCriticConfig
from robot_hoi.rl.models import ActorCritic
from robot_hoi.student.config import ComplexMimicConfig
from robot_hoi.student.difficulty import (
    DifficultyAwareSampler,
    ema,
    group_means,
    learnability,
    motion_probabilities,
)
from robot_hoi.student.experts import expand_inputs, route_by_success
from robot_hoi.student.height_map import HeightMap, grid_offsets, top_surface_heights
from robot_hoi.student.samplers import StartSampler
from robot_hoi.student.student_env import EpisodeBatch


def softmax(values):
    exps = [math.exp(v) for v in values]
    return [e / sum(exps) for e in exps]


def test_building_blocks():
    assert ema(torch.tensor(1.0), torch.tensor(0.0), 0.95).item() == pytest.approx(0.95)
    assert group_means(torch.tensor([0.2, 0.6, 1.0]), torch.tensor([0, 0, 1]), 2).tolist() == pytest.approx([0.4, 1.0])
    u = learnability(torch.tensor([0.0, 0.1, 0.3, -0.2]), threshold=0.1, strength=1.0)
    assert u.tolist() == pytest.approx([math.exp(-0.1), 1.0, 1.0, math.exp(-0.3)])


def test_motion_probabilities_eq_5_to_9():
    cfg = ComplexMimicConfig()  # tau_inter = tau_intra = 1, eps = 0.05, eps_u = 0.1, lambda_u = 1
    difficulty, improvement = torch.tensor([0.2, 0.6, 1.0]), torch.tensor([0.2, 0.0, 0.5])
    groups = torch.tensor([0, 0, 1])
    p_group = softmax([0.4, 1.0])
    within0 = softmax([0.2, 0.6 - 0.1])  # s = D + log u, u(m2) = exp(-0.1)
    expected = [0.95 * p_group[0] * within0[0] + 0.05 / 3, 0.95 * p_group[0] * within0[1] + 0.05 / 3,
                0.95 * p_group[1] + 0.05 / 3]
    p = motion_probabilities(difficulty, improvement, groups, 2, cfg)
    assert p.tolist() == pytest.approx(expected, rel=1e-5) and p.sum().item() == pytest.approx(1.0)
    # ablations
    no_inter = motion_probabilities(difficulty, improvement, groups, 2, ComplexMimicConfig(inter_group=False))
    assert no_inter[2].item() == pytest.approx(0.95 / 3 + 0.05 / 3)  # group 1 holds 1 of 3 motions
    no_intra = motion_probabilities(difficulty, improvement, groups, 2, ComplexMimicConfig(intra_group=False))
    assert no_intra[0].item() == pytest.approx(no_intra[1].item())
    no_filter = motion_probabilities(difficulty, improvement, groups, 2, ComplexMimicConfig(learnability_filter=False))
    within = softmax([0.2, 0.6])
    assert no_filter[1].item() == pytest.approx(0.95 * p_group[0] * within[1] + 0.05 / 3, rel=1e-5)


def batch(clips, success, returns):
    return EpisodeBatch(clip=torch.tensor(clips), success=torch.tensor(success, dtype=torch.float32),
                        ret=torch.tensor(returns, dtype=torch.float32), length=torch.ones(len(clips)))


def test_sampler_updates_difficulty_and_learnability_from_episodes():
    das = DifficultyAwareSampler([0, 0, 1], ComplexMimicConfig())
    das.observe(batch([0, 0, 1], [1, 0, 0], [10.0, 20.0, 5.0]))
    das.update()
    # f = [0.5, 1.0, -]; D = 0.95 * 0 + 0.05 * f; clip 2 had no episode and keeps D = 0
    assert das.difficulty.tolist() == pytest.approx([0.025, 0.05, 0.0])
    assert das.improvement.tolist() == [0.0, 0.0, 0.0]  # no previous return yet
    das.observe(batch([0, 1], [1, 0], [25.0, 3.0]))
    das.update()
    # clip 0: f = 0, Delta R = 25 - 15 = 10, I = 0.1 * 10; clip 1: f = 1, Delta R = 3 - 5 = -2, I = 0.1 * -2
    assert das.difficulty.tolist() == pytest.approx([0.95 * 0.025, 0.95 * 0.05 + 0.05, 0.0])
    assert das.improvement.tolist() == pytest.approx([1.0, -0.2, 0.0])
    restored = DifficultyAwareSampler([0, 0, 1], ComplexMimicConfig())
    restored.load_state_dict(das.state_dict())
    assert torch.equal(restored.probabilities(), das.probabilities())


def test_start_sampler_draws_clips_with_the_given_probabilities():
    sampler = StartSampler(8, 2, torch.Generator().manual_seed(0), lambda: torch.tensor([0.9, 0.1]))

    class Env:
        device = torch.device("cpu")

        class cfg:
            class init:
                stand_start_probability = 0.3

    counts = torch.zeros(2)
    for _ in range(250):
        plan = sampler.plan(Env, torch.arange(8))
        assert not plan.custom.any() and plan.state is None
        counts += torch.bincount(plan.clip, minlength=2)
    assert counts[1] / counts.sum() == pytest.approx(0.1, abs=0.03)


def test_routing():
    assert route_by_success([1.0, 0.5, 0.25, 0.0], threshold=0.5) == [0, 0, 1, 1]


def test_height_map_rays_and_grid():
    offsets = grid_offsets(20, 0.08)
    assert offsets.shape == (400, 2) and offsets[0].tolist() == pytest.approx([-0.76, -0.76])
    assert (offsets[1] - offsets[0]).tolist() == pytest.approx([0.08, 0.0])
    # one triangle on the plane z = 1 + x over the unit square's lower-left half
    tri = torch.tensor([[[[0.0, 0.0, 1.0], [1.0, 0.0, 2.0], [0.0, 1.0, 1.0]]]])
    heights = top_surface_heights(torch.tensor([[[0.25, 0.25], [0.9, 0.9], [-0.1, 0.5]]]), tri)
    assert heights[0].tolist() == pytest.approx([1.25, 0.0, 0.0])


def test_height_map_sees_the_box_heading_aligned():
    box = HeightMap(box_asset((0.42, 0.42, 0.3)))
    root, upright = torch.tensor([[0.0, 0.0, 0.8]]), torch.tensor([[1.0, 0.0, 0.0, 0.0]])
    obj_pos, obj_quat = torch.tensor([[0.6, 0.0, 0.15]]), torch.tensor([[1.0, 0.0, 0.0, 0.0]])
    grid = box.heights(root, upright, obj_pos, obj_quat).reshape(20, 20)  # [y, x]
    # x in {0.44 .. 0.76} (5 columns) and |y| <= 0.2 (6 rows) lie on the box top at 0.3 m
    assert (grid > 0).sum() == 30 and grid.max().item() == pytest.approx(0.3)
    assert (grid[7:13, 15:20] == pytest.approx(0.3))
    # turn the robot 90 degrees left: the box is now on its right (negative local y)
    left = torch.tensor([[math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)]])
    turned = box.heights(root, left, obj_pos, obj_quat).reshape(20, 20)
    assert (turned > 0).sum() == 30 and (turned[:5, 7:13] == pytest.approx(0.3))


def test_interaction_expert_starts_as_the_teacher():
    torch.manual_seed(0)
    cfg = ActorCriticConfig(actor_hidden_dims=[16], critic_hidden_dims=[16])
    teacher = ActorCritic(6, 8, 3, cfg)
    teacher.update_normalizers(torch.randn(50, 6), torch.randn(50, 8))
    expert = ActorCritic(6 + 4, 8 + 4, 3, cfg)
    state = expand_inputs(teacher.state_dict(), "actor", 4, torch.full((4,), 0.3), torch.full((4,), 2.0))
    expert.load_state_dict(expand_inputs(state, "critic", 4, torch.zeros(4), torch.ones(4)))
    obs, critic, height = torch.randn(5, 6), torch.randn(5, 8), torch.rand(5, 4)
    assert torch.allclose(expert.act_inference(torch.cat([obs, height], 1)), teacher.act_inference(obs))
    assert torch.allclose(expert.evaluate(torch.cat([critic, height], 1)), teacher.evaluate(critic))
    assert expert.actor_normalizer.mean[-4:].tolist() == pytest.approx([0.3] * 4)


def test_env_start_hook_resets_envs_onto_the_sampled_clips(scene):
    from .conftest import make_env, make_reference

    env = make_env(scene, [make_reference(scene, 20, name="a"), make_reference(scene, 30, name="b")], num_envs=6)
    env.start_sampler = StartSampler(6, 2, torch.Generator().manual_seed(0), lambda: torch.tensor([0.0, 1.0]))
    env.reset()
    assert (env.clip_id == 1).all()
    assert ((env.ref_index >= env.clip_start[1]) & (env.ref_index <= env.clip_end[1])).all()
    for _ in range(3):
        env.step(torch.zeros(6, env.num_actions))
    assert (env.clip_id == 1).all()
