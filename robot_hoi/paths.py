"""Where things live: configs/, urdf/ and policies/, and the optional ../shared reference folder.

A checkout keeps configs/, urdf/ and policies/ at the repository root; an installed wheel carries them inside this
package (setup.py maps them in). Every path to them is built here.
"""

from __future__ import annotations

import os
from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent
_INSTALLED = (_PACKAGE / "configs").is_dir()
REPO_ROOT: Path | None = None if _INSTALLED else _PACKAGE.parent  # the checkout; None under an installed wheel
DATA_ROOT = _PACKAGE if _INSTALLED else _PACKAGE.parent
CONFIGS_DIR = DATA_ROOT / "configs"
URDF_DIR = DATA_ROOT / "urdf"
POLICIES_DIR = DATA_ROOT / "policies"
TASK_CONFIG = CONFIGS_DIR / "tasks" / "interaction.yaml"  # the interaction task (teachers, eval, export)
# Where exports go unless told: the checkout's policies/, or ./policies under a wheel (never into site-packages).
EXPORT_DIR = POLICIES_DIR if REPO_ROOT is not None else Path("policies")


def shared_dir() -> Path | None:
    """The reference folder (papers, robot files, real clips), or None on a machine without it.

    ROBOT_HOI_SHARED overrides the default ../shared next to the repository.
    """
    env = os.environ.get("ROBOT_HOI_SHARED")
    if env:
        path = Path(env)
    elif REPO_ROOT is not None:
        path = REPO_ROOT.parent / "shared"
    else:
        return None
    return path if path.is_dir() else None


def cache_dir() -> Path:
    """Where results that take long to compute and never change for the same inputs are kept between runs (e.g.
    object convex decompositions): ROBOT_HOI_CACHE, else $XDG_CACHE_HOME/robot-hoi, else ~/.cache/robot-hoi."""
    env = os.environ.get("ROBOT_HOI_CACHE")
    if env:
        return Path(env)
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "robot-hoi"
