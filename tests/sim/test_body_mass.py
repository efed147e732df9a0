"""Per-environment body masses (domain randomisation): each backend steps every env with its own mass."""

import importlib.util

import mujoco
import numpy as np
import pytest
import torch

from robot_hoi.sim import make_backend
from robot_hoi.utils.mujoco_model import with_body_mass

from .conftest import ARM_ON_BOX_XML

BACKENDS = ["cpu"] + (["warp"] if importlib.util.find_spec("mujoco_warp") else [])


def test_with_body_mass_scales_inertia_and_recomputes_derived_constants():
    model = mujoco.MjModel.from_xml_string(ARM_ON_BOX_XML)
    base = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "base")
    heavy = with_body_mass(model, base, 2.0)
    assert heavy.body_mass[base] == 2.0 and model.body_mass[base] == 1.0  # a copy: the original is unchanged
    np.testing.assert_allclose(heavy.body_inertia[base], 2.0 * model.body_inertia[base])
    np.testing.assert_allclose(heavy.body_subtreemass[base], 2.3)  # itself + the 0.3 kg arm
    assert heavy.body_invweight0[base, 0] < model.body_invweight0[base, 0]
    with pytest.raises(ValueError, match="positive"):
        with_body_mass(model, base, 0.0)


@pytest.mark.parametrize("name", BACKENDS)
def test_each_env_steps_with_its_own_mass(name):
    """The same upward force lifts the 1 kg body (1.3 kg with its arm) and lets the 2 kg one (2.3 kg) fall."""
    model = mujoco.MjModel.from_xml_string(ARM_ON_BOX_XML)
    base = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "base")
    backend = make_backend(name, model, num_envs=3, decimation=4, device="cpu" if name == "warp" else None)
    backend.set_body_mass_levels(base, [1.0, 2.0])
    backend.select_body_mass(torch.tensor([1]), torch.tensor([1]))
    backend.set_state(torch.arange(3), torch.as_tensor(model.qpos0).repeat(3, 1), torch.zeros(3, model.nv))
    wrench = torch.zeros(3, model.nbody, 6)
    wrench[:, base, 2] = 1.5 * 1.3 * 9.81
    for _ in range(20):  # 0.4 s
        backend.step(torch.zeros(3, 1), wrench)
    z = backend.qpos[:, 2].double().cpu()
    assert z[0] > 0.5 + 0.02 and z[2] > 0.5 + 0.02  # light: rises
    assert z[1] < 0.5 - 0.02                        # heavy: falls
    assert torch.allclose(z[0], z[2], atol=1e-6)    # the untouched envs keep the model's mass
    # back to the model's mass: env 1 now rises like the others
    backend.select_body_mass(torch.tensor([1]), torch.tensor([0]))
    backend.set_state(torch.arange(3), torch.as_tensor(model.qpos0).repeat(3, 1), torch.zeros(3, model.nv))
    for _ in range(10):
        backend.step(torch.zeros(3, 1), wrench)
    z = backend.qpos[:, 2].double().cpu()
    assert torch.allclose(z[1], z[0], atol=1e-5)
