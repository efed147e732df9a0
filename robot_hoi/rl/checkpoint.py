"""PPO checkpoints: plain dicts of tensors, numbers and strings, written atomically and read with
`torch.load(weights_only=True)` (nothing is unpickled). The resolved config travels as a JSON string, together
with the observation layout and the git commit/diff of the code that trained it.
"""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import torch

from deploy.atomic import atomic_path
from robot_hoi.errors import UserError
from robot_hoi.paths import REPO_ROOT
from robot_hoi.rl.config import TrainConfig
from robot_hoi.rl.models import ActorCritic

CHECKPOINT_FORMAT = "robot_hoi.ppo"
CHECKPOINT_VERSION = 1
_MAX_DIFF_CHARS = 2_000_000  # a runaway diff (e.g. a committed dataset) must not bloat every checkpoint
_REQUIRED_KEYS = ("model", "config_json", "dims", "iteration")


def git_state(repo: Path | None = REPO_ROOT) -> dict[str, str]:
    """Commit hash and uncommitted diff of `repo`; empty strings when git or the repository is unavailable (None:
    an installed wheel, whose site-packages may sit inside some unrelated repository)."""
    if repo is None:
        return {"commit": "", "diff": ""}

    def run(*args: str) -> str:
        try:
            out = subprocess.run(
                ["git", "-C", str(repo), *args], capture_output=True, text=True, timeout=20, check=True
            )
        except (OSError, subprocess.SubprocessError):
            return ""
        return out.stdout

    diff = run("diff", "HEAD")
    if len(diff) > _MAX_DIFF_CHARS:
        diff = diff[:_MAX_DIFF_CHARS] + "\n[diff truncated]\n"
    return {"commit": run("rev-parse", "HEAD").strip(), "diff": diff}


def save_checkpoint(path: str | Path, payload: dict[str, Any]) -> Path:
    """Write a checkpoint atomically (a crash never leaves a half-written file under `path`)."""
    path = Path(path)
    payload = {"format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION, **payload}
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)
    return path


def read_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """Load and sanity-check a checkpoint; UserError naming the file when it is missing or not ours."""
    path = Path(path)
    if not path.is_file():
        raise UserError(f"{path}: checkpoint not found")
    try:
        data = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as exc:  # truncated file, foreign pickle, wrong format: all a bad user file
        raise UserError(f"{path}: not a readable checkpoint ({type(exc).__name__}: {exc})") from None
    if not isinstance(data, dict) or data.get("format") != CHECKPOINT_FORMAT:
        raise UserError(f"{path}: not a robot-hoi PPO checkpoint")
    if data.get("version") != CHECKPOINT_VERSION:
        raise UserError(
            f"{path}: checkpoint version {data.get('version')} (this code reads {CHECKPOINT_VERSION})"
        )
    missing = [k for k in _REQUIRED_KEYS if k not in data]
    if missing:
        raise UserError(f"{path}: checkpoint lacks {missing}")
    return data


def load_model_state(model: ActorCritic, state: dict, source: str | Path) -> None:
    try:
        model.load_state_dict(state)
    except RuntimeError as exc:
        first = str(exc).splitlines()[0] if str(exc) else "mismatch"
        raise UserError(f"{source}: weights do not fit this model ({first})") from None


def load_policy(
    path: str | Path, device: str | torch.device = "cpu"
) -> tuple[ActorCritic, TrainConfig, dict]:
    """Rebuild the trained ActorCritic from a checkpoint alone (no env needed), in eval mode.

    Returns (model, config, checkpoint dict). checkpoint["obs_layout"] has the actor/critic groups and sizes.
    """
    data = read_checkpoint(path, map_location=device)
    cfg = TrainConfig.from_json(data["config_json"], f"{path} (stored config)")
    dims = data["dims"]
    model = ActorCritic(dims["actor_obs"], dims["critic_obs"], dims["num_actions"], cfg.model).to(device)
    load_model_state(model, data["model"], path)
    model.eval()
    return model, cfg, data


def prune_checkpoints(directory: Path, keep_last: int | None, pattern: str = "model_*.pt") -> None:
    """Delete all but the newest `keep_last` periodic checkpoints (by iteration number in the name)."""
    if keep_last is None:
        return

    def iteration(p: Path) -> int:
        try:
            return int(p.stem.split("_")[-1])
        except ValueError:
            return -1

    found = sorted((p for p in directory.glob(pattern) if iteration(p) >= 0), key=iteration)
    for old in found[:-keep_last]:
        old.unlink(missing_ok=True)


BEST_CHECKPOINT = "model_best.pt"  # the in-training evaluation's best policy (runner.eval_interval)


def latest_checkpoint(folder: Path) -> Path | None:
    """model_final.pt, else the model_<it>.pt with the highest iteration: where training resumes."""
    final = folder / "model_final.pt"
    if final.exists():
        return final
    numbered = [(int(p.stem.split("_")[-1]), p) for p in folder.glob("model_*.pt") if p.stem.split("_")[-1].isdigit()]
    return max(numbered)[1] if numbered else None


def policy_checkpoint(folder: Path) -> Path | None:
    """The policy a finished run stands for: the in-training evaluation's best when there is one, else the latest.
    (PPO's checkpoints can alternate between completing a clip and not; the best is the one to use.)"""
    best = folder / BEST_CHECKPOINT
    return best if best.exists() else latest_checkpoint(folder)


def resolve_checkpoint(path: str | Path) -> Path:
    """A checkpoint file as given, or the policy checkpoint of a group folder, or of the one group of a run folder
    that holds checkpoints (model_best.pt, else model_final.pt, else the highest iteration)."""
    path = Path(path)
    if path.is_file():
        return path
    if not path.is_dir():
        raise UserError(f"{path}: no such checkpoint or run folder")
    found = policy_checkpoint(path)
    if found is not None:
        return found
    groups = {sub.name: policy_checkpoint(sub) for sub in sorted(path.iterdir()) if sub.is_dir()}
    groups = {name: ckpt for name, ckpt in groups.items() if ckpt is not None}
    if len(groups) == 1:
        return next(iter(groups.values()))
    if not groups:
        raise UserError(f"{path}: no model_*.pt in this folder or its group folders")
    raise UserError(f"{path}: several groups have checkpoints ({', '.join(groups)}); name one, e.g. "
                    f"{path / next(iter(groups))}")
