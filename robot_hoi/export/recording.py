"""What an export records beside the network: the action-offset keys of the contract and the observations a
policy meets, for verifying the ONNX file against torch."""

from __future__ import annotations

import numpy as np
import torch


def offset_settings(env_cfg) -> dict:
    """The contract's action-offset keys for a training env: its mode ("reference" or "fixed" = the default pose),
    the warmup length and whether the reference offset glides in over the warmup."""
    mode = "reference" if env_cfg.action_offset == "reference" else "fixed"
    return {"action_offset_mode": mode, "warmup_frames": env_cfg.warmup_frames,
            "warmup_blend": env_cfg.warmup_blend and mode == "reference"}


def record_observations(env, policy_fn, group: str, count: int):
    """Observations of `group` met while running `policy_fn` in `env` (for export verification)."""
    recorded = []
    obs = env.reset()
    with torch.no_grad():
        while sum(len(r) for r in recorded) < count:
            recorded.append(obs[group].numpy().copy())
            obs, *_ = env.step(policy_fn(obs))
    return np.concatenate(recorded)[:count]
