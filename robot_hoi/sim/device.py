"""Where the physics and the policy run: decided once per process and handed down as concrete settings.

`resolve_physics(backend, sim_device)` turns a config's `auto` into `cpu` or `warp` on one device and checks the
choice: the warp backend shares its arrays with torch zero-copy, so warp must see the CUDA device torch sees.
When torch sees CUDA and warp does not (warp-lang's PyPI wheel needs a newer driver than torch's), the answer is
a one-line error, not a silent run of every world on warp's CPU device. `resolve_env_cfg` applies it to an env
config: a process builds its training env, evaluation envs and rollouts from the one resolved config, so they all
land where its policy expects them. A CUDA device defaults to this process's current one
(`torch.cuda.current_device()`): the rank's device under torch.distributed, the Ray worker's under Ray.
"""

from __future__ import annotations

import copy
import functools
import importlib.util

import torch

from robot_hoi.errors import UserError

WARP_DRIVER_HINT = ("warp-lang's PyPI wheels (1.19+) are built with CUDA 13 and need an NVIDIA R580+ driver; on an "
                    "R535-R570 driver install the +cu12 wheel from https://github.com/NVIDIA/warp/releases")


def import_warp():
    """(warp, mujoco_warp), initialised quietly; a UserError when they are not installed."""
    try:
        import warp

        warp.config.quiet = True  # before mujoco_warp initialises warp
        warp.config.log_level = warp.LOG_WARNING  # no per-module load lines
        import mujoco_warp
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise UserError("the warp backend needs mujoco-warp and warp-lang: pip install -e '.[warp]'") from exc
    warp.init()
    return warp, mujoco_warp


def warp_installed() -> bool:
    return importlib.util.find_spec("mujoco_warp") is not None


@functools.cache
def warp_cuda_device_count() -> int:
    """CUDA devices warp can use (0 when its wheel does not fit the driver). Imports warp: seconds on a CPU box."""
    wp, _ = import_warp()
    return wp.get_cuda_device_count()


def current_cuda_device() -> str:
    return f"cuda:{torch.cuda.current_device()}"


def resolve_physics(backend: str, sim_device: str | None) -> tuple[str, str | None]:
    """(backend, warp device) for a config's `backend` (auto | cpu | warp) and `sim_device` (None: default).

    auto: warp on this process's CUDA device when torch sees CUDA and mujoco-warp is installed, else cpu.
    warp: on `sim_device`, else this process's CUDA device, else warp's CPU device."""
    if backend == "cpu":
        return "cpu", None
    if backend not in ("auto", "warp"):
        raise UserError(f"unknown physics backend {backend!r} (choose cpu, warp or auto)")
    if not warp_installed():
        if backend == "auto":
            return "cpu", None
        raise UserError("the warp backend needs mujoco-warp and warp-lang: pip install -e '.[warp]'")
    torch_cuda = torch.cuda.is_available()
    if backend == "auto" and not torch_cuda:
        return "cpu", None
    device = sim_device or (current_cuda_device() if torch_cuda else "cpu")
    if device.startswith("cuda") and torch_cuda and warp_cuda_device_count() == 0:
        raise UserError(f"torch sees CUDA but warp does not: {WARP_DRIVER_HINT} (or run --backend cpu)")
    return "warp", device


def resolve_env_cfg(cfg):
    """A copy of an env config (backend, sim_device) with the physics resolved (idempotent)."""
    backend, device = resolve_physics(cfg.backend, cfg.sim_device)
    resolved = copy.deepcopy(cfg)
    resolved.backend, resolved.sim_device = backend, device
    return resolved


PHYSICS_BYTES_PER_WORLD = 260_000  # measured: ~254 KB of mujoco_warp data per world (G1 + Inspire + object)


def check_gpu_memory(cfg) -> None:
    """Refuse a warp pool whose physics alone does not fit in its GPU's free memory (e.g. fractional Ray GPUs
    packing several teachers onto one), rather than failing on an allocation minutes later."""
    if cfg.backend != "warp" or not str(cfg.sim_device).startswith("cuda"):
        return
    free, _ = torch.cuda.mem_get_info(torch.device(cfg.sim_device))
    need = cfg.num_envs * PHYSICS_BYTES_PER_WORLD
    if need > free:
        raise UserError(f"{cfg.num_envs} warp worlds need ~{need / 1e9:.1f} GB on {cfg.sim_device} for the physics "
                        f"alone, {free / 1e9:.1f} GB are free (teachers sharing the GPU? raise --gpus-per-teacher or "
                        "lower env.num_envs)")


def physics_device(cfg) -> torch.device:
    """The torch device of a resolved env config's physics tensors."""
    return torch.device(cfg.sim_device if cfg.backend == "warp" else "cpu")


def module_device(module: torch.nn.Module, default: torch.device | str) -> torch.device:
    """Where a model's parameters (or buffers) are; `default` for one that holds none."""
    tensor = next(iter([*module.parameters(), *module.buffers()]), None)
    return torch.device(default) if tensor is None else tensor.device


def policy_device(requested: str, env_device: torch.device | str) -> torch.device:
    """`auto`: the physics' device when it is a GPU, else this process's CUDA device when there is one, else the
    CPU; any other value as given."""
    if requested != "auto":
        return torch.device(requested)
    env_device = torch.device(env_device)
    if env_device.type == "cuda":
        return env_device
    return torch.device(current_cuda_device() if torch.cuda.is_available() else "cpu")
