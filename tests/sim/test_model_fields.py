"""Per-environment model fields and per-sub-step targets (domain randomisation) on each backend."""

import importlib.util

import mujoco
import pytest
import torch

from robot_hoi.sim import make_backend

from .conftest import ARM_ON_BOX_XML

BACKENDS = ["cpu"] + (["warp"] if importlib.util.find_spec("mujoco_warp") else [])
FIELDS = ("actuator_gainprm", "actuator_biasprm")


def _backend(name, model, fields=FIELDS):
    backend = make_backend(name, model, num_envs=3, decimation=4, device="cpu" if name == "warp" else None,
                           variable_fields=fields)
    backend.set_state(torch.arange(3), torch.as_tensor(model.qpos0).repeat(3, 1), torch.zeros(3, model.nv))
    return backend


def _hinge(backend, model):
    return backend.qpos[:, model.jnt_qposadr[1]].double().cpu()


@pytest.mark.parametrize("name", BACKENDS)
def test_an_env_with_softer_gains_lags_the_others(name):
    model = mujoco.MjModel.from_xml_string(ARM_ON_BOX_XML)
    backend = _backend(name, model)
    gain = torch.as_tensor(model.actuator_gainprm)[None].clone()
    bias = torch.as_tensor(model.actuator_biasprm)[None].clone()
    gain[..., 0] *= 0.2
    bias[..., 1] *= 0.2
    backend.write_model_fields(torch.tensor([1]), {"actuator_gainprm": gain, "actuator_biasprm": bias})
    for _ in range(5):
        backend.step(torch.full((3, 1), 0.5))
    q = _hinge(backend, model)
    assert q[1] < 0.6 * q[0] and torch.allclose(q[0], q[2], atol=1e-6)


@pytest.mark.parametrize("name", BACKENDS)
def test_per_sub_step_targets(name):
    """Equal sub-step targets step like one target; a target that arrives late moves the arm less."""
    model = mujoco.MjModel.from_xml_string(ARM_ON_BOX_XML)
    one, per = _backend(name, model, ()), _backend(name, model, ())
    target = torch.full((3, 1), 0.5)
    late = target[:, None].repeat(1, 4, 1)
    late[1, :3] = 0.0  # env 1: the new target arrives at the last sub-step
    one.step(target)
    per.step(late)
    a, b = _hinge(one, model), _hinge(per, model)
    assert torch.allclose(a[[0, 2]], b[[0, 2]], atol=1e-6)
    assert b[1] < 0.5 * a[1]


def test_the_gpu_backend_refuses_a_field_it_was_not_told_about():
    pytest.importorskip("mujoco_warp")
    model = mujoco.MjModel.from_xml_string(ARM_ON_BOX_XML)
    backend = _backend("warp", model, ())
    with pytest.raises(ValueError, match="geom_friction"):
        backend.write_model_fields(torch.tensor([0]), {"geom_friction": torch.zeros(1, model.ngeom, 3)})
