"""Reference distillation: a teacher rollout becomes the reference (states, links, object, contacts per frame)."""

import numpy as np
import pytest
import torch

from robot_hoi.errors import DataError
from robot_hoi.student.reference_distill import load_reference, rollout_reference, save_reference
from robot_hoi.tasks.interaction.reference import nearest_surface_vectors
from robot_hoi.utils.torch_rot import quat_apply

from .conftest import make_env, make_reference

FRAMES = 40


def rollout_env(scene, **overrides):
    env = make_env(scene, [make_reference(scene, FRAMES)], num_envs=1, **overrides)
    env.cfg.init.stand_start_probability = 1.0
    env.cfg.init.spawn_noise_xy = 0.0
    return env


def test_a_successful_rollout_records_every_frame_but_the_last(scene):
    env = rollout_env(scene)
    hold = lambda obs: torch.zeros(1, env.num_actions)  # noqa: E731 - stand: the reference stands too
    result = rollout_reference(env, hold, min_frames=10, failure_margin=5)
    assert not result.terminated
    assert result.frames_reached == FRAMES - 1 and result.clip_frames == FRAMES
    ref = result.reference
    assert ref.num_frames == FRAMES - 1
    # what the simulation achieved: the pelvis stays near the stand height, the box where it rests
    assert (ref.robot_qpos[:, 2] - 0.79).abs().max() < 0.1
    assert torch.allclose(ref.object_pos, torch.tensor([0.6, 0.0, 0.15]).expand(FRAMES - 1, 3), atol=0.02)
    assert ref.hand_contact.dtype == torch.bool and not ref.hand_contact.any()
    # d_hat is recomputed from the achieved links and object
    points = quat_apply(ref.object_quat_wxyz[:, None], ref.object_points[None]) + ref.object_pos[:, None]
    assert torch.allclose(ref.d_hat, nearest_surface_vectors(ref.link_pos, points))
    # the links recorded at frame f are the simulation's at the step that tracked frame f
    assert torch.allclose(ref.link_pos[-1], env.references[0].link_pos[-2], atol=0.05)


def test_an_early_termination_cuts_the_margin_or_drops_the_clip(scene):
    env = rollout_env(scene)
    env.cfg.warmup_frames = 0  # the fall starts tracking at once
    fall = lambda obs: torch.full((1, env.num_actions), 4.0)  # noqa: E731 - every joint to its limit
    result = rollout_reference(env, fall, min_frames=2, failure_margin=3)
    assert result.terminated and 0 < result.frames_reached < FRAMES - 1
    expected = result.frames_reached - 3
    if expected >= 2:
        assert result.reference.num_frames == expected
    else:
        assert result.reference is None
    dropped = rollout_reference(rollout_env(scene), fall, min_frames=FRAMES, failure_margin=3)
    assert dropped.reference is None and "dropped" in dropped.describe()


class FingersPastTheirLimit:
    """The env as a teacher's rollout can see it: fingers pressed open sit 0.7 mrad below their lower limit (MuJoCo's
    soft joint limits), which is what made every deploy tick of a distilled student clamp its targets."""

    def __init__(self, env):
        self._env = env
        self.fingers = [i for i in range(env.num_actions) if i not in env.body_actuator_ids]

    def __getattr__(self, name):
        return getattr(self._env, name)

    @property
    def joint_pos(self):
        q = self._env.joint_pos.clone()
        q[:, self.fingers] = self._env.ctrl_low[self.fingers] - 7e-4
        return q


def test_recorded_joints_are_clipped_into_the_control_range(scene):
    env = FingersPastTheirLimit(rollout_env(scene))
    result = rollout_reference(env, lambda obs: torch.zeros(1, env.num_actions), min_frames=10, failure_margin=5)
    ref = result.reference
    # a zero action's PD target (action_offset "reference") is reachable on every frame
    assert bool(((ref.joint_pos > env.ctrl_low) & (ref.joint_pos < env.ctrl_high)).all())
    assert torch.allclose(ref.joint_pos[:, env.fingers], env.ctrl_low[env.fingers].expand(ref.num_frames, -1),
                          atol=1e-4)
    assert torch.equal(ref.robot_qpos[:, torch.as_tensor(env.layout.actuator_qpos)], ref.joint_pos)


def test_saved_reference_round_trips_without_pickle(scene, tmp_path):
    ref = make_reference(scene, 12, drift=0.02)
    path = tmp_path / "ref.npz"
    save_reference(ref, path, {"teacher": "t0", "frames_reached": 12})
    back, meta = load_reference(path)
    assert meta["teacher"] == "t0" and meta["frames_reached"] == 12 and back.name == ref.name
    for name in ("link_pos", "robot_qpos", "object_quat_wxyz", "d_hat", "hand_contact", "object_points"):
        assert torch.equal(getattr(back, name), getattr(ref, name)), name
    with np.load(path, allow_pickle=False) as data:  # plain arrays only
        assert "meta_json" in data.files
    (tmp_path / "bad.npz").write_bytes(b"not an npz")
    with pytest.raises(DataError, match="bad.npz"):
        load_reference(tmp_path / "bad.npz")
