"""Reference distillation (InterMimic Sec. 3.3): a teacher's rollout replaces the MoCap clip as the student's
reference and reward target.

The teacher runs its clip from the default stand (with the approach warm-up) to the clip's end, deterministically
(action = mean). Every step records what the simulation achieved for the reference frame of that step: robot
state, mapped links, object, and the simulated hand contact (supp. C: the student's reference contact comes from
the force detector on the distilled reference). If the teacher terminates early, the frames just before the
failure are cut as well; a rollout shorter than `min_frames` drops the clip (the teachers filter out data too
corrupted to imitate, supp. H). The last frame of a clip is not recorded (the env resets on reaching it).

The recorded joint angles are clipped into the actuators' control range: MuJoCo's soft joint limits let a finger
pressed open sit a fraction of a milliradian below its lower limit, and the student's (and the deployed policy's)
PD target is these joints plus a correction (action_offset "reference"), so an unclipped reference would ask for
an unreachable target, clamped on every tick, even for a zero action. The clip keeps 10 urad inside the limits,
so that float32 rounding of a limit cannot put a recorded angle back outside it.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from deploy.atomic import atomic_path
from robot_hoi.errors import DataError
from robot_hoi.tasks.interaction.reference import ReferenceMotion, nearest_surface_vectors
from robot_hoi.utils.torch_rot import quat_apply

FORMAT = 2  # 2: joint angles clipped into the control range (distilled references of format 1 are re-made)
LIMIT_MARGIN = 1e-5  # rad
RECORDED = ("link_pos", "link_quat_wxyz", "robot_qpos", "robot_qvel", "joint_pos", "object_pos",
            "object_quat_wxyz", "object_lin_vel", "object_ang_vel", "hand_contact")


@dataclass
class RolloutResult:
    reference: ReferenceMotion | None  # None: the teacher failed too early, the clip is dropped
    frames_reached: int  # reference frames the teacher tracked before its episode ended
    clip_frames: int
    terminated: bool
    mean_reward: float

    def describe(self) -> str:
        kept = 0 if self.reference is None else self.reference.num_frames
        end = "terminated" if self.terminated else "reached the end"
        return (f"{end} at frame {self.frames_reached}/{self.clip_frames}, mean reward {self.mean_reward:.3f}, "
                f"kept {kept} frames" + (" (dropped)" if self.reference is None else ""))


def inside_limits(joint_pos: Tensor, low: Tensor, high: Tensor) -> Tensor:
    """Joint angles clipped into [low, high], LIMIT_MARGIN inside."""
    return torch.maximum(torch.minimum(joint_pos, high - LIMIT_MARGIN), low + LIMIT_MARGIN)


def _env_snapshot(env) -> dict[str, Tensor]:
    lay = env.layout
    qpos, qvel = env.backend.qpos.to(torch.float32), env.backend.qvel.to(torch.float32)
    return {
        "link_pos": env.link_pos, "link_quat_wxyz": env.link_quat,
        "robot_qpos": qpos[:, : lay.robot_nq], "robot_qvel": qvel[:, : lay.robot_nv],
        "joint_pos": env.joint_pos, "object_pos": env.object_pos, "object_quat_wxyz": env.object_quat,
        "object_lin_vel": env.object_lin_vel, "object_ang_vel": env.object_ang_vel,
        "hand_contact": env.hand_contact_found,
    }


@torch.no_grad()
def rollout_reference(env, policy: Callable[[dict[str, Tensor]], Tensor], min_frames: int,
                      failure_margin: int) -> RolloutResult:
    """Roll `policy` in `env` (one clip, num_envs 1, starting from the stand) and build the distilled reference."""
    if env.num_envs != 1 or len(env.references) != 1:
        raise ValueError("reference rollouts run one env on one clip")
    source = env.references[0]
    total = source.num_frames
    recorded = {name: [None] * total for name in RECORDED}
    obs = env.reset()
    start = int(env.clip_start[0])
    reached, terminated, rewards = 0, False, []
    for _ in range(env.max_episode_length + 1):
        obs, reward, term, trunc, _ = env.step(policy(obs))
        rewards.append(float(reward[0]))
        if bool(term[0] | trunc[0]):
            terminated = bool(term[0])
            break
        frame = int(env.ref_index[0]) - start
        for name, value in _env_snapshot(env).items():
            recorded[name][frame] = value[0].cpu()  # a reference is a host object (saved, reloaded on any device)
        reached = frame + 1
    keep = reached - failure_margin if terminated else reached
    mean_reward = float(np.mean(rewards)) if rewards else 0.0
    if keep < min_frames:
        return RolloutResult(None, reached, total, terminated, mean_reward)
    stacked = {name: torch.stack(values[:keep]) for name, values in recorded.items()}
    stacked["joint_pos"] = inside_limits(stacked["joint_pos"], env.ctrl_low.cpu(), env.ctrl_high.cpu())
    stacked["robot_qpos"][:, torch.as_tensor(env.layout.actuator_qpos)] = stacked["joint_pos"]
    points_world = quat_apply(stacked["object_quat_wxyz"][:, None], source.object_points[None]) + \
        stacked["object_pos"][:, None]
    reference = ReferenceMotion(
        fps=source.fps, object_points=source.object_points, name=source.name,
        d_hat=nearest_surface_vectors(stacked["link_pos"], points_world), **stacked)
    return RolloutResult(reference, reached, total, terminated, mean_reward)


def save_reference(reference: ReferenceMotion, path: str | Path, meta: dict) -> None:
    """npz of plain arrays (read back without pickle) + the metadata as a JSON string."""
    arrays = {f.name: getattr(reference, f.name).numpy() for f in fields(reference)
              if isinstance(getattr(reference, f.name), Tensor)}
    arrays["meta_json"] = np.array(json.dumps({**meta, "fps": reference.fps, "name": reference.name}))
    with atomic_path(path, suffix=".npz") as tmp:
        with open(tmp, "wb") as handle:
            np.savez(handle, **arrays)


def load_reference(path: str | Path) -> tuple[ReferenceMotion, dict]:
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError) as exc:
        raise DataError(f"{path}: not a readable distilled reference ({exc})") from None
    try:
        meta = json.loads(str(arrays.pop("meta_json")))
        tensors = {k: torch.as_tensor(v) for k, v in arrays.items()}
        tensors["hand_contact"] = tensors["hand_contact"].bool()
        reference = ReferenceMotion(fps=float(meta["fps"]), name=str(meta["name"]), **tensors)
    except (KeyError, TypeError, json.JSONDecodeError) as exc:
        raise DataError(f"{path}: distilled reference lacks {exc}") from None
    return reference, meta
