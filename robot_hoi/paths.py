"""Where things live: the repository (configs/, urdf/, policies/) and the optional ../shared reference folder."""

from __future__ import annotations

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
CONFIGS_DIR = REPO_ROOT / "configs"
URDF_DIR = REPO_ROOT / "urdf"
POLICIES_DIR = REPO_ROOT / "policies"
TASK_CONFIG = CONFIGS_DIR / "tasks" / "interaction.yaml"  # the interaction task (teachers, eval, export)


def shared_dir() -> Path | None:
    """The reference folder (papers, robot files, real clips), or None on a machine without it.

    ROBOT_HOI_SHARED overrides the default ../shared next to the repository.
    """
    env = os.environ.get("ROBOT_HOI_SHARED")
    path = Path(env) if env else REPO_ROOT.parent / "shared"
    return path if path.is_dir() else None
