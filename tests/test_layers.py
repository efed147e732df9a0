"""The house's layering holds: import-linter's contracts in pyproject.toml (pipeline layers with the commands on
top, shared helpers below every stage, deploy/ alone, sim2sim/ above deploy)."""

from __future__ import annotations

import shutil
import subprocess
import sys

import pytest

from robot_hoi.paths import REPO_ROOT


@pytest.mark.skipif(REPO_ROOT is None, reason="needs the checkout's pyproject.toml")
def test_import_contracts_are_kept():
    lint = shutil.which("lint-imports")
    if lint is None:
        pytest.skip("import-linter is not installed (pip install -e '.[dev]')")
    result = subprocess.run([lint, "--no-cache"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    assert "0 broken" in result.stdout


def test_no_library_module_imports_a_command_module():
    """The commands package is a leaf: importing every library stage leaves it unimported."""
    stages = ["data", "embodiment", "sim", "retarget", "tasks", "rl", "student", "export", "utils"]
    code = ("import importlib, pkgutil, sys\n"
            f"for stage in {stages!r}:\n"
            "    package = importlib.import_module('robot_hoi.' + stage)\n"
            "    for m in pkgutil.walk_packages(package.__path__, package.__name__ + '.'):\n"
            "        importlib.import_module(m.name)\n"
            "print(sorted(n for n in sys.modules if n.startswith('robot_hoi.commands')))\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    assert result.stdout.strip() == "[]"
