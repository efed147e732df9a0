"""Worker processes import only numpy, mujoco, onnxruntime, deploy and sim2sim: no torch, no robot_hoi.sim."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_episode_modules_do_not_pull_in_torch():
    code = ("import sys, sim2sim.episode, sim2sim.runner, sim2sim.video; "
            "bad = [m for m in ('torch', 'robot_hoi.sim', 'robot_hoi.tasks') if m in sys.modules]; "
            "print(bad); sys.exit(1 if bad else 0)")
    result = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr


def test_cli_registration_is_light():
    code = ("import sys, argparse, sim2sim.cli; p = argparse.ArgumentParser(); s = p.add_subparsers(); "
            "sim2sim.cli.register(s); heavy = [m for m in ('mujoco', 'torch', 'onnxruntime') if m in sys.modules]; "
            "print(heavy); sys.exit(1 if heavy else 0)")
    result = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
