"""The task config's retarget setting (leg-load compensation) reaches the reference the env tracks, and a cached
reference made with the other setting is refused instead of silently reused."""

import numpy as np
import pytest

from robot_hoi.embodiment import load_embodiment
from robot_hoi.errors import UserError
from robot_hoi.tasks.interaction import factory
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg


def test_leg_load_setting_reaches_the_env_and_guards_the_cache(tmp_path):
    embodiment = load_embodiment("g1_inspire")
    clip = factory.load_source("embedded:lift_place")
    plain = factory.load_or_retarget(clip, embodiment, None)
    cfg = InteractionEnvCfg(num_envs=2, backend="cpu", retarget_leg_loads=True)
    env = factory.make_env([clip], cfg, embodiment, cache=tmp_path)
    cached = tmp_path / f"{clip.name}.npz"
    assert cached.is_file()

    legs = [i for i, n in enumerate(embodiment.actuator_names) if any(k in n for k in ("hip", "knee", "ankle"))]
    arms = [i for i, n in enumerate(embodiment.actuator_names) if "shoulder" in n or "elbow" in n]
    tracked = env.ref_joint_pos.cpu().numpy()  # PD targets of every frame (one clip)
    leg_shift = np.abs(tracked[:, legs] - plain.joint_pos[:, legs]).max()
    assert leg_shift > 0.02  # the stance torques / kp moved the leg targets
    np.testing.assert_allclose(tracked[:, arms], plain.joint_pos[:, arms], atol=1e-5)  # arms as before
    np.testing.assert_allclose(plain.qpos, factory.load_or_retarget(clip, embodiment, cached.parent, True).qpos,
                               atol=1e-6)  # same states: only the PD targets differ

    with pytest.raises(UserError, match=rf"{cached.name}.*leg-load compensation on.*asks for it off"):
        factory.make_env([clip], InteractionEnvCfg(num_envs=2, backend="cpu"), embodiment, cache=tmp_path)
