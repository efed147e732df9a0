"""Student policy latency: the exported ONNX graph in ONNX Runtime vs the same network in torch eager.

Batch 1, one thread each (what the robot's control loop runs), deterministic action mean with the observation
normaliser baked in. The network is the g1_inspire student (deploy-contract observation: 41 actuators,
keyframes {1, 2, 4, 16}, 27 reference links -> 698 inputs) with the paper's Transformer (3 layers, 4 heads,
width 256, feed-forward 512), or a trained one from --checkpoint. Prints p50/p99 of both and the speed-up, and
finishes with one line:

    student_ort_p99_ms: <ORT p99 in milliseconds>

Goal: p99 < 1 ms and >= 3x faster than torch eager. Example: python bench/student_latency.py --runs 5000
"""

from __future__ import annotations

import argparse
import time
from types import SimpleNamespace

import numpy as np
import torch


def contract_spec(embodiment_name: str, keyframes: tuple[int, ...]) -> list[dict]:
    from deploy.contract import NUM_HAND_ACTUATORS, OBS_TERMS
    from robot_hoi.embodiment import load_embodiment

    emb = load_embodiment(embodiment_name)
    actuators = len(emb.actuator_names)
    dims = SimpleNamespace(actuators=actuators, body=actuators - NUM_HAND_ACTUATORS, keyframes=len(keyframes),
                           links=len(emb.link_map))
    return [{"name": name, "size": size(dims)} for name, size in OBS_TERMS.items()]


def build_policy(args: argparse.Namespace) -> tuple[torch.nn.Module, int]:
    if args.checkpoint:
        from robot_hoi.student.checkpoint import load_student

        model, _, _ = load_student(args.checkpoint)
        return model.exported_policy().eval(), model.num_actor_obs
    from robot_hoi.rl.config import ActorCriticConfig
    from robot_hoi.student.config import TransformerConfig
    from robot_hoi.student.model import StudentActorCritic
    from robot_hoi.student.tokens import token_layout

    keyframes = (1, 2, 4, 16)
    layout = token_layout(contract_spec(args.embodiment, keyframes), keyframes)
    torch.manual_seed(0)
    model = StudentActorCritic(layout, 64, 41, TransformerConfig(), ActorCriticConfig(critic_hidden_dims=[64]))
    return model.exported_policy().eval(), layout.obs_dim


def percentiles(times_s: list[float]) -> tuple[float, float]:
    ms = np.asarray(times_s) * 1e3
    return float(np.percentile(ms, 50)), float(np.percentile(ms, 99))


def time_calls(fn, runs: int, warmup: int) -> list[float]:
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return times


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--checkpoint", default=None, help="a student model_*.pt (default: an untrained student)")
    parser.add_argument("--embodiment", default="g1_inspire")
    parser.add_argument("--runs", type=int, default=3000, help="timed calls per backend")
    parser.add_argument("--warmup", type=int, default=200)
    args = parser.parse_args(argv)

    from deploy.contract import INPUT_NAME, OUTPUT_NAME
    from robot_hoi.export.onnx_export import ort_session, to_onnx_bytes

    torch.set_num_threads(1)
    policy, obs_dim = build_policy(args)
    session = ort_session(to_onnx_bytes(policy, obs_dim, {}))
    obs = np.random.default_rng(0).normal(size=(1, obs_dim)).astype(np.float32)
    obs_t = torch.from_numpy(obs)
    with torch.no_grad():
        error = float(np.abs(session.run([OUTPUT_NAME], {INPUT_NAME: obs})[0] - policy(obs_t).numpy()).max())
        torch_times = time_calls(lambda: policy(obs_t), args.runs, args.warmup)
    ort_times = time_calls(lambda: session.run([OUTPUT_NAME], {INPUT_NAME: obs}), args.runs, args.warmup)
    ort_p50, ort_p99 = percentiles(ort_times)
    torch_p50, torch_p99 = percentiles(torch_times)
    print(f"student: {obs_dim} observations, {sum(p.numel() for p in policy.parameters()):,} parameters, "
          f"ORT vs torch max |diff| {error:.1e}")
    print(f"onnxruntime  (batch 1, 1 thread): p50 {ort_p50:.3f} ms  p99 {ort_p99:.3f} ms")
    print(f"torch eager  (batch 1, 1 thread): p50 {torch_p50:.3f} ms  p99 {torch_p99:.3f} ms")
    print(f"speed-up: p50 {torch_p50 / ort_p50:.1f}x  p99 {torch_p99 / ort_p99:.1f}x "
          f"(goal: ORT p99 < 1 ms, >= 3x)")
    print(f"student_ort_p99_ms: {ort_p99:.3f}")


if __name__ == "__main__":
    main()
