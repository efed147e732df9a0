"""The env recomputes only the reset rows of its state after a reset (issue 15): the same values, bit for bit, as
the full recompute it replaces, and the same step outputs."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from robot_hoi.data.objects import box_asset
from robot_hoi.embodiment import load_embodiment
from robot_hoi.tasks.interaction.env import InteractionEnv, ReferenceFrame
from robot_hoi.tasks.interaction.scene_setup import InteractionScene

from .test_bookkeeping import force_terminations, make_env


@pytest.fixture(scope="module")
def scene():
    return InteractionScene(load_embodiment("g1_inspire"), box_asset((0.4, 0.4, 0.3)))


def _full_update(env):
    """The old behaviour: every row recomputed whatever env_ids says."""
    env._update_state = lambda env_ids=None: InteractionEnv._update_state(env)


def _resets(step: int) -> torch.Tensor:
    """Envs 1 and 3 end their episode on alternate steps (never all envs at once)."""
    forced = torch.zeros(5, dtype=torch.bool)
    forced[1 + 2 * (step % 2)] = True
    return forced


def _assert_same(a, b, name):
    if isinstance(a, ReferenceFrame):
        for field in vars(a):
            _assert_same(getattr(a, field), getattr(b, field), f"{name}.{field}")
        return
    assert a.dtype == b.dtype and a.shape == b.shape, name
    assert torch.equal(a, b), f"{name} differs from a full update"


def test_partial_update_equals_a_full_update_bit_for_bit(scene):
    env = make_env(scene, num_envs=5, joint_noise=0.05, stand=0.5)
    force_terminations(env, _resets)
    gen = torch.Generator().manual_seed(0)
    for _ in range(4):
        env.step(0.3 * torch.randn(5, env.num_actions, generator=gen))
        full = SimpleNamespace()
        env._compute_state(full, None)
        for name, value in vars(full).items():
            _assert_same(getattr(env, name), value, name)


def test_steps_match_the_full_update_after_resets(scene):
    """Same seed, actions and forced resets: observations, rewards, dones and logs equal those of an env that
    recomputes every row after each reset (as before issue 15)."""
    envs = [make_env(scene, num_envs=5, joint_noise=0.05, stand=0.5) for _ in range(2)]
    _full_update(envs[1])
    for env in envs:
        force_terminations(env, _resets)
    gen = torch.Generator().manual_seed(1)
    for _ in range(5):
        actions = 0.3 * torch.randn(5, envs[0].num_actions, generator=gen)
        (obs_a, rew_a, term_a, trunc_a, ext_a), (obs_b, rew_b, term_b, trunc_b, ext_b) = (e.step(actions) for e in envs)
        for group in obs_a:
            assert torch.equal(obs_a[group], obs_b[group]), group
        assert torch.equal(rew_a, rew_b) and torch.equal(term_a, term_b) and torch.equal(trunc_a, trunc_b)
        assert ext_a["log"].keys() == ext_b["log"].keys()
        for key, value in ext_a["log"].items():
            assert torch.equal(torch.as_tensor(value), torch.as_tensor(ext_b["log"][key])), key
    assert torch.equal(envs[0].link_acc, envs[1].link_acc)
    assert torch.equal(envs[0].contact_loss_frames, envs[1].contact_loss_frames)


def test_cpu_backend_holds_controls_and_wrenches_over_the_sub_steps(scene):
    """The step writes float32 targets and wrenches into its float64 control buffers without temporaries: every
    sub-step gets exactly the converted values."""
    backend = scene.make_backend(3, backend="cpu", nthread=1)
    gen = torch.Generator().manual_seed(2)
    ctrl = torch.randn(3, backend.nu, generator=gen)
    wrench = torch.randn(3, scene.model.nbody, 6, generator=gen)
    backend.step(ctrl, wrench)
    expected = np.repeat(ctrl.double().numpy()[:, None], backend.decimation, axis=1)
    assert np.array_equal(backend._ctrl, expected)
    assert np.array_equal(backend._ctrl_wrench[:, :, : backend.nu], expected)
    assert np.array_equal(backend._ctrl_wrench[:, :, backend.nu:],
                          np.repeat(wrench.double().numpy().reshape(3, 1, -1), backend.decimation, axis=1))
    backend.step(ctrl)  # wrenches once applied are cleared, not kept
    assert not backend._ctrl_wrench[:, :, backend.nu:].any()


def test_step_reports_its_stages_to_timers(scene):
    from robot_hoi.utils.timing import Timers

    env = make_env(scene, num_envs=2)
    env.timers = timers = Timers()
    env.step(torch.zeros(2, env.num_actions))
    assert set(timers.seconds) == {"physics", "state_rewards_terminations", "observations", "resets"}
