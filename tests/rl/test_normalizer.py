from __future__ import annotations

import io
import warnings

import numpy as np
import onnxruntime as ort
import torch

from robot_hoi.rl.config import ActorCriticConfig
from robot_hoi.rl.models import ActorCritic
from robot_hoi.rl.normalizer import RunningNormalizer


def test_running_statistics_match_numpy_over_uneven_batches():
    rng = np.random.default_rng(0)
    batches = [rng.normal(loc=3.0, scale=[0.5, 2.0, 10.0], size=(n, 3)) for n in (1, 7, 64, 250)]
    norm = RunningNormalizer(3, clip=100.0)
    for b in batches:
        norm.update(torch.as_tensor(b, dtype=torch.float32))
    data = np.concatenate(batches)
    np.testing.assert_allclose(norm.mean.numpy(), data.mean(axis=0), rtol=1e-5)
    np.testing.assert_allclose(norm.var.numpy(), data.var(axis=0), rtol=1e-4)
    assert float(norm.count) == len(data)
    x = torch.as_tensor(data[:5], dtype=torch.float32)
    expected = (data[:5] - data.mean(0)) / np.sqrt(data.var(0) + norm.eps)
    np.testing.assert_allclose(norm(x).numpy(), expected, rtol=1e-4, atol=1e-5)


def test_frozen_in_eval_and_clipped():
    norm = RunningNormalizer(2, clip=2.0)
    norm.update(torch.tensor([[0.0, 0.0], [2.0, 2.0]]))  # mean 1, var 1
    norm.eval()
    norm.update(torch.full((10, 2), 50.0))
    assert torch.allclose(norm.mean, torch.ones(2)) and float(norm.count) == 2
    out = norm(torch.tensor([[100.0, -100.0]]))
    assert torch.equal(out, torch.tensor([[2.0, -2.0]]))


def test_statistics_are_buffers_baked_into_onnx():
    torch.manual_seed(0)
    model = ActorCritic(5, 6, 3, ActorCriticConfig(actor_hidden_dims=[16], critic_hidden_dims=[16]))
    model.update_normalizers(torch.randn(100, 5) * 4 + 2, torch.randn(100, 6))
    assert {"actor_normalizer.mean", "actor_normalizer.var", "log_std"} <= set(model.state_dict())
    policy = model.exported_policy().eval()
    obs = torch.randn(4, 5) * 4 + 2
    buf = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(policy, (obs,), buf, dynamo=False, input_names=["obs"], output_names=["actions"])
    session = ort.InferenceSession(buf.getvalue())
    (onnx_out,) = session.run(None, {"obs": obs.numpy()})
    np.testing.assert_allclose(onnx_out, model.act_inference(obs).detach().numpy(), atol=1e-5)
    # The raw-obs path really normalises: without the statistics the output differs.
    assert not torch.allclose(model.actor(obs), model.act_inference(obs))
