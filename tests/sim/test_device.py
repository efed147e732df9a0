"""Device choice (robot_hoi/sim/device.py): once per process, asking warp, the rank's CUDA device by default."""

import pytest
import torch

from robot_hoi.errors import UserError
from robot_hoi.sim import device as dev
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg


@pytest.fixture
def cuda_box(monkeypatch):
    """torch sees CUDA (this process on cuda:3, as a DDP rank or Ray worker would be); warp's answer is set per test."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "current_device", lambda: 3)
    monkeypatch.setattr(dev, "warp_installed", lambda: True)

    def warp_sees(count: int) -> None:
        monkeypatch.setattr(dev, "warp_cuda_device_count", lambda: count)

    return warp_sees


def test_cpu_stays_cpu_and_unknown_backends_are_refused():
    assert dev.resolve_physics("cpu", "cuda:0") == ("cpu", None)
    with pytest.raises(UserError, match="tpu"):
        dev.resolve_physics("tpu", None)


def test_auto_without_cuda_is_the_cpu_backend_and_warp_runs_on_its_cpu_device(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert dev.resolve_physics("auto", None) == ("cpu", None)
    if dev.warp_installed():
        assert dev.resolve_physics("warp", None) == ("warp", "cpu")


def test_cuda_defaults_to_this_process_device(cuda_box):
    cuda_box(4)
    assert dev.resolve_physics("auto", None) == ("warp", "cuda:3")
    assert dev.resolve_physics("warp", None) == ("warp", "cuda:3")
    assert dev.resolve_physics("warp", "cuda:1") == ("warp", "cuda:1")
    assert dev.policy_device("auto", torch.device("cpu")) == torch.device("cuda:3")
    assert dev.policy_device("auto", torch.device("cuda:1")) == torch.device("cuda:1")
    assert dev.policy_device("cpu", torch.device("cuda:1")) == torch.device("cpu")


def test_torch_sees_cuda_warp_does_not_is_one_line_naming_the_driver(cuda_box):
    cuda_box(0)
    for backend in ("auto", "warp"):
        with pytest.raises(UserError) as info:
            dev.resolve_physics(backend, None)
        message = str(info.value)
        assert "\n" not in message and "R580" in message and "cu12" in message
    assert dev.resolve_physics("warp", "cpu") == ("warp", "cpu")  # asked for warp's CPU device: no error


def test_resolved_env_config_is_concrete_and_resolving_again_changes_nothing(cuda_box):
    cuda_box(1)
    cfg = InteractionEnvCfg()
    resolved = dev.resolve_env_cfg(cfg)
    assert (resolved.backend, resolved.sim_device) == ("warp", "cuda:3")
    assert (cfg.backend, cfg.sim_device) == ("auto", None)  # the given config is left as it was
    again = dev.resolve_env_cfg(resolved)
    assert (again.backend, again.sim_device) == ("warp", "cuda:3")
    assert dev.physics_device(resolved) == torch.device("cuda:3")


def test_a_warp_pool_that_does_not_fit_the_free_gpu_memory_is_refused(monkeypatch):
    cfg = InteractionEnvCfg(num_envs=4096)
    cfg.backend, cfg.sim_device = "warp", "cuda:0"
    monkeypatch.setattr(torch.cuda, "mem_get_info", lambda device: (int(0.5e9), int(80e9)))
    with pytest.raises(UserError, match="--gpus-per-teacher"):
        dev.check_gpu_memory(cfg)
    monkeypatch.setattr(torch.cuda, "mem_get_info", lambda device: (int(40e9), int(80e9)))
    dev.check_gpu_memory(cfg)
    cfg.sim_device = "cpu"
    dev.check_gpu_memory(cfg)  # warp's CPU device: nothing to check
