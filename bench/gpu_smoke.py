"""GPU smoke test of the MuJoCo Warp path: what a first run on a lent GPU should report, in a few minutes.

1. capabilities: torch/warp versions, CUDA driver, whether warp sees the GPU torch sees, conditional graphs,
   memory pool; how the step runs (CUDA graph captured or kernel launches);
2. parity: 8 worlds against the CPU backend (same states and targets, 15 control steps, compared on the CPU);
3. throughput at --worlds: physics-only control steps/s and full env steps/s (observations, rewards, resets);
4. overflow flags and the high-water marks of constraint rows and contacts per world over those steps;
5. a --train-seconds teacher training (PPO, fast preset) with samples/s and memory high-water marks.
Ends with `env_steps_per_s: <full env steps/s at --worlds>`.

    python bench/gpu_smoke.py                                    # a CUDA machine: 4096 worlds, 2 min training
    python bench/gpu_smoke.py --device cpu --worlds 8 --train-seconds 20 --steps 10   # warp's CPU device

Without --device cpu on a machine without CUDA it says so and exits 0.
"""

from __future__ import annotations

import argparse
import time

import torch

PARITY_WORLDS, PARITY_STEPS, PARITY_QPOS_ATOL = 8, 15, 1e-3


def capabilities(device: str) -> dict[str, object]:
    from robot_hoi.sim.device import import_warp, warp_cuda_device_count

    wp, _ = import_warp()
    caps: dict[str, object] = {"torch": torch.__version__, "torch_cuda": torch.version.cuda, "warp": wp.__version__,
                               "cuda_driver": wp.get_cuda_driver_version(),
                               "warp_cuda_devices": warp_cuda_device_count()}
    if device.startswith("cuda"):
        caps.update(gpu=torch.cuda.get_device_name(torch.device(device)),
                    conditional_graphs=wp.is_conditional_graph_supported(),
                    mempool=wp.is_mempool_enabled(wp.get_device(device)))
    return caps


def _sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize(torch.device(device))


def parity(scene, device: str) -> float:
    """Largest qpos difference after PARITY_STEPS control steps of PARITY_WORLDS worlds (compared on the CPU)."""
    n, model, layout = PARITY_WORLDS, scene.model, scene.layout
    cpu, warp = scene.make_backend(n, "cpu"), scene.make_backend(n, "warp", device=device)
    qpos = torch.tensor(model.qpos0, dtype=torch.float64).repeat(n, 1)
    qpos[:, : layout.robot_nq] = scene.default_robot_qpos().double()
    qpos[:, layout.object_qpos:layout.object_qpos + 3] = torch.tensor([0.45, 0.0, 0.4], dtype=torch.float64)
    qpos[:, layout.object_qpos] += torch.linspace(0.0, 0.1, n, dtype=torch.float64)
    qvel = torch.zeros(n, model.nv, dtype=torch.float64)
    for backend in (cpu, warp):
        backend.set_state(torch.arange(n), qpos, qvel)
    generator = torch.Generator().manual_seed(0)
    default = torch.tensor(scene.embodiment.default_pos, dtype=torch.float64)
    for _ in range(PARITY_STEPS):
        ctrl = default + 0.03 * torch.randn(n, model.nu, generator=generator, dtype=torch.float64)
        cpu.step(ctrl)
        warp.step(ctrl.to(warp.device))
    return float((warp.qpos.double().cpu() - cpu.qpos).abs().max())


def physics_rate(scene, device: str, worlds: int, steps: int) -> tuple[float, object]:
    """Physics-only control steps/s; the backend (its overflow report read after every step)."""
    backend = scene.make_backend(worlds, "warp", device=device)
    ctrl = torch.tensor(scene.embodiment.default_pos, dtype=torch.float32, device=backend.device).repeat(worlds, 1)
    backend.step(ctrl)
    _sync(device)
    elapsed = 0.0
    for _ in range(steps):
        t0 = time.perf_counter()
        backend.step(ctrl)
        _sync(device)
        elapsed += time.perf_counter() - t0
        backend.physics_report()  # not timed: it reads the flags back to the host
    return worlds * steps / elapsed, backend


def env_and_training(device: str, worlds: int, steps: int, train_seconds: float) -> dict[str, float]:
    """Full env steps/s with zero-mean noisy actions, its physics report, then a PPO run of `train_seconds`."""
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.rl.budget import Budget
    from robot_hoi.rl.config import PRESETS, load_train_config
    from robot_hoi.rl.runner import OnPolicyRunner
    from robot_hoi.tasks.interaction import factory
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg

    cfg = InteractionEnvCfg(num_envs=worlds, backend="warp", sim_device=device)
    env = factory.make_env([factory.load_source("embedded:lift_carry")], cfg, load_embodiment("g1_inspire"))
    actions = torch.zeros(worlds, env.num_actions, device=env.device)
    env.reset()
    env.step(actions)
    _sync(device)
    t0 = time.perf_counter()
    for _ in range(steps):
        env.step(actions + 0.05 * torch.randn_like(actions))
    _sync(device)
    out = {"env_steps_per_s": worlds * steps / (time.perf_counter() - t0)}
    out.update(env.backend.physics_report())
    train_cfg = load_train_config(PRESETS["fast"], ["runner.progress=false", "runner.tensorboard=false"])
    if device.startswith("cuda"):
        torch.cuda.reset_peak_memory_stats(torch.device(device))
    runner = OnPolicyRunner(env, train_cfg, None, device=env.device)
    stats = runner.learn(Budget(wall_seconds=train_seconds))
    out.update(train_iterations=stats["iterations"], train_samples_per_s=stats["samples"] / stats["wall_s"],
               train_mean_return=stats["mean_return"])
    out.update({f"train_{k}": v for k, v in runner.physics_report().items()})
    if device.startswith("cuda"):
        import warp as wp

        out.update(torch_peak_memory_gb=torch.cuda.max_memory_allocated(torch.device(device)) / 1e9,
                   warp_peak_memory_gb=wp.get_mempool_used_mem_high(device) / 1e9)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cuda", help="cuda[:N] (default: this process's CUDA device) or cpu")
    parser.add_argument("--worlds", type=int, default=4096)
    parser.add_argument("--steps", type=int, default=100, help="control steps timed per throughput figure")
    parser.add_argument("--train-seconds", type=float, default=120.0)
    args = parser.parse_args()
    torch.set_num_threads(1)
    from robot_hoi.sim.device import current_cuda_device, warp_installed

    device = args.device
    if device.startswith("cuda"):
        if not torch.cuda.is_available():
            print("no CUDA device here: nothing to smoke-test (--device cpu --worlds 8 runs warp's CPU device)")
            print("gpu_smoke: skipped")
            return 0
        device = current_cuda_device() if device == "cuda" else device
    if not warp_installed():
        print("mujoco-warp is not installed: pip install -e '.[warp]'")
        return 1
    from robot_hoi.data.synth import default_clip
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.sim.device import resolve_physics
    from robot_hoi.sim.warp_backend import CONSTRAINT_ROWS, CONTACTS_PER_WORLD
    from robot_hoi.tasks.interaction.scene_setup import InteractionScene

    resolve_physics("warp", device)  # the driver check: a one-line error when warp cannot use this GPU
    print("capabilities: " + ", ".join(f"{k} {v}" for k, v in capabilities(device).items()))
    scene = InteractionScene(load_embodiment("g1_inspire"), default_clip().object)
    error = parity(scene, device)
    verdict = "ok" if error <= PARITY_QPOS_ATOL else "FAILED"
    print(f"parity: {PARITY_WORLDS} worlds x {PARITY_STEPS} control steps vs the CPU backend, max |qpos| "
          f"difference {error:.2e} (tolerance {PARITY_QPOS_ATOL:g}): {verdict}")
    rate, backend = physics_rate(scene, device, args.worlds, args.steps)
    print(f"physics: {args.worlds} worlds on {device}, stepping by {backend.stepping}: {rate:,.0f} control steps/s; "
          f"high water: {backend.high_water['constraint_rows']} of {CONSTRAINT_ROWS} constraint rows, "
          f"{backend.high_water['contacts_per_world']} of {CONTACTS_PER_WORLD} contacts per world; no buffer overflow")
    del backend
    results = env_and_training(device, args.worlds, args.steps, args.train_seconds)
    for key, value in results.items():
        print(f"  {key}: {value:,.4g}" if isinstance(value, float) else f"  {key}: {value}")
    print(f"env_steps_per_s: {results['env_steps_per_s']:.0f}")
    return 0 if verdict == "ok" else 1


if __name__ == "__main__":
    raise SystemExit(main())
