"""Token layout, the Transformer student, its PPO compatibility and its ONNX export (normaliser baked in)."""

import numpy as np
import pytest
import torch

from deploy.contract import INPUT_NAME, OUTPUT_NAME
from robot_hoi.errors import UserError
from robot_hoi.export.onnx_export import ort_session, to_onnx_bytes
from robot_hoi.rl.config import ActorCriticConfig, PPOConfig
from robot_hoi.rl.ppo import PPO
from robot_hoi.student.config import TransformerConfig
from robot_hoi.student.model import StudentActorCritic
from robot_hoi.student.tokens import TokenLayout, token_layout

SPEC = [{"name": "joint_pos", "size": 3}, {"name": "ref_a", "size": 8}, {"name": "object_pos", "size": 2},
        {"name": "ref_b", "size": 4}]


def test_token_layout_splits_reference_terms_by_keyframe():
    layout = token_layout(SPEC, (1, 16))
    assert layout.obs_dim == 17
    assert layout.state_index == (0, 1, 2, 11, 12)
    # ref_a: 3..10 -> keyframe 1: 3..6, keyframe 16: 7..10; ref_b: 13..16 -> 13,14 | 15,16
    assert layout.keyframe_index == ((3, 4, 5, 6, 13, 14), (7, 8, 9, 10, 15, 16))
    assert layout.keyframes == (1, 16) and layout.keyframe_width == 6
    assert TokenLayout.from_dict(layout.to_dict()) == layout


def test_token_layout_rejects_reference_terms_that_do_not_split():
    with pytest.raises(UserError, match="does not split"):
        token_layout([{"name": "joint_pos", "size": 3}, {"name": "ref_a", "size": 7}], (1, 2))
    with pytest.raises(UserError, match="no proprioception"):
        token_layout([{"name": "ref_a", "size": 4}], (1, 2))


def small_student(layout, critic_dim=5, actions=4, learn_std=True):
    torch.manual_seed(0)
    cfg = TransformerConfig(width=32, heads=4, layers=2, feedforward=64)
    return StudentActorCritic(layout, critic_dim, actions, cfg,
                              ActorCriticConfig(critic_hidden_dims=[16], learn_std=learn_std, init_log_std=-1.0))


def test_student_tokens_and_keyframe_sensitivity():
    layout = token_layout(SPEC, (1, 16))
    model = small_student(layout).eval()
    x = torch.randn(6, layout.obs_dim)
    assert model.actor.tokens(x).shape == (6, 3, 32)
    mean = model.act_inference(x)
    assert mean.shape == (6, 4)
    # the initial mean is near zero (the env's default action) ...
    assert mean.abs().max() < 0.5
    # ... and depends on every token: change only the second keyframe's entries
    y = x.clone()
    y[:, list(layout.keyframe_index[1])] += 1.0
    assert not torch.allclose(model.act_inference(y), mean)
    # swapping the two keyframe blocks changes the output: position embeddings tell the keyframes apart
    z = x.clone()
    z[:, list(layout.keyframe_index[0])], z[:, list(layout.keyframe_index[1])] = \
        x[:, list(layout.keyframe_index[1])], x[:, list(layout.keyframe_index[0])]
    assert not torch.allclose(model.act_inference(z), mean)


def test_student_trains_with_ppo_and_keeps_the_actor_critic_interface():
    layout = token_layout(SPEC, (1, 16))
    model = small_student(layout)
    cfg = PPOConfig(horizon=4, minibatch_size=None, num_minibatches=2, num_epochs=2, actor_lr=1e-3)
    alg = PPO(model, cfg)
    alg.init_storage(8, layout.obs_dim, 5, 4, {"teacher_mean": 4})
    alg.extra_actor_loss = lambda extra, mean: (mean - extra["teacher_mean"]).square().sum(-1).mean()
    before = {k: v.clone() for k, v in model.state_dict().items()}
    for _ in range(4):
        obs, critic = torch.randn(8, layout.obs_dim), torch.randn(8, 5)
        given = torch.randn(8, 4)
        assert torch.equal(alg.act(obs, critic, {"teacher_mean": torch.ones(8, 4)}, actions=given), given)
        alg.process_env_step(torch.rand(8), torch.zeros(8, dtype=torch.bool), torch.zeros(8, dtype=torch.bool))
    alg.compute_returns(torch.randn(8, 5))
    stats = alg.update()
    assert stats["extra_actor_loss"] > 0
    after = model.state_dict()
    assert not torch.equal(before["actor.head.weight"], after["actor.head.weight"])
    assert not torch.equal(before["critic.0.weight"], after["critic.0.weight"])
    assert not torch.equal(before["log_std"], after["log_std"])
    assert float(after["actor_normalizer.count"]) == 32  # 4 steps x 8 envs folded into the running statistics


def test_onnx_export_matches_torch_with_the_normaliser_baked_in():
    layout = token_layout(SPEC, (1, 16))
    model = small_student(layout)
    model.update_normalizers(3.0 + 2.0 * torch.randn(500, layout.obs_dim), torch.randn(500, 5))
    model.eval()
    policy = model.exported_policy()
    session = ort_session(to_onnx_bytes(policy, layout.obs_dim, {"policy_kind": '"student"'}))
    obs = np.random.default_rng(1).normal(3.0, 2.0, size=(1000, layout.obs_dim)).astype(np.float32)
    got = session.run([OUTPUT_NAME], {INPUT_NAME: obs})[0]
    with torch.no_grad():
        expected = policy(torch.from_numpy(obs)).numpy()
    assert got.shape == (1000, 4)
    assert np.abs(got - expected).max() < 1e-4
    # the baked normaliser matters: the raw network on unnormalised inputs answers differently
    with torch.no_grad():
        raw = model.actor(torch.from_numpy(obs)).numpy()
    assert np.abs(raw - expected).max() > 1e-3
