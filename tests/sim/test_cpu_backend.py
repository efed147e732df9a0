"""The CPU backend must reproduce plain sequential MuJoCo stepping, batched."""

import mujoco
import numpy as np
import torch

from robot_hoi.sim import make_backend

from .conftest import ARM_ON_BOX_XML


def test_batched_step_matches_sequential_mujoco():
    model = mujoco.MjModel.from_xml_string(ARM_ON_BOX_XML)
    backend = make_backend("cpu", model, num_envs=4, decimation=5, nthread=2)
    targets = torch.linspace(-1.0, 1.0, 4)[:, None].to(torch.float64)
    for _ in range(20):
        backend.step(targets)

    for env in range(4):
        data = mujoco.MjData(model)
        for _ in range(20 * 5):
            data.ctrl[:] = targets[env].numpy()
            mujoco.mj_step(model, data)
        np.testing.assert_allclose(backend.qpos[env].numpy(), data.qpos, atol=1e-10)
        np.testing.assert_allclose(backend.qvel[env].numpy(), data.qvel, atol=1e-9)
    # envs with different targets ended in different arm angles: no cross-talk between environments
    assert len(set(np.round(backend.qpos[:, 7].numpy(), 4))) == 4


def test_set_state_recomputes_sensors_exactly():
    model = mujoco.MjModel.from_xml_string(ARM_ON_BOX_XML)
    backend = make_backend("cpu", model, num_envs=3, decimation=4, nthread=2)
    backend.step(torch.zeros(3, 1))
    qpos = backend.qpos.clone()
    qpos[1, 2] = 1.7
    qpos[1, 7] = 0.4
    before_other = backend.sensordata[0].clone()
    backend.set_state(torch.tensor([1]), qpos[1:2], torch.zeros(1, model.nv))

    data = mujoco.MjData(model)
    data.qpos[:] = qpos[1].numpy()
    mujoco.mj_forward(model, data)
    np.testing.assert_allclose(backend.sensordata[1].numpy(), data.sensordata, atol=1e-12)
    assert backend.qpos[1, 2].item() == 1.7
    assert torch.equal(backend.sensordata[0], before_other)  # untouched environments keep their readings
