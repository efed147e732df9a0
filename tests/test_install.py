"""Installs without the checkout: the repository's wheel (configs, URDF and policies inside it) trains from a folder
elsewhere, and the robot-side distribution (deploy/pyproject.toml) installs without torch or MuJoCo and completes a
dry run against the simulated hands. Each builds a wheel from a copy of the working tree into a fresh venv; both
skip when the package index cannot be reached."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
NETWORK_ERRORS = ("NewConnectionError", "Failed to establish a new connection", "Temporary failure in name resolution",
                  "Network is unreachable", "ConnectTimeoutError", "Read timed out")


def _env() -> dict[str, str]:
    """The caller's environment without anything that would put the checkout on the path."""
    return {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "ROBOT_HOI_SHARED", "DEPLOY_CONFIG_DIR")}


def _pip(python: Path, *args: str, cwd: Path) -> None:
    proc = subprocess.run([str(python), "-m", "pip", "--no-input", *args], cwd=cwd, env=_env(),
                          capture_output=True, text=True, timeout=600)
    if proc.returncode != 0:
        output = proc.stdout + proc.stderr
        if any(s in output for s in NETWORK_ERRORS):
            pytest.skip(f"package index unreachable: pip {args[0]} failed with a connection error")
        pytest.fail(f"pip {' '.join(args)} failed:\n{output[-4000:]}")


def _copy(src: Path, parts: list[str]) -> None:
    ignore = shutil.ignore_patterns("__pycache__", "build", "*.egg-info")
    for part in parts:
        if (REPO / part).is_dir():
            shutil.copytree(REPO / part, src / part, ignore=ignore)
        else:
            (src / part).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / part, src / part)


def _wheel(project: Path, out: Path) -> Path:
    _pip(Path(sys.executable), "wheel", "--no-deps", "-q", "-w", str(out), str(project), cwd=out.parent)
    (wheel,) = out.glob("*.whl")
    return wheel


def _venv(path: Path) -> Path:
    subprocess.run([sys.executable, "-m", "venv", str(path)], check=True, env=_env(), timeout=300)
    return path / "bin" / "python"


def _run(argv: list[str], cwd: Path, timeout: float) -> subprocess.CompletedProcess:
    return subprocess.run(argv, cwd=cwd, env=_env(), capture_output=True, text=True, timeout=timeout)


def test_the_deploy_distribution_names_every_subpackage():
    """deploy/pyproject.toml lists its packages (it cannot search for them: the folder is the package)."""
    listed = set(tomllib.loads((REPO / "deploy" / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {"deploy"} | {"deploy." + ".".join(p.parent.relative_to(REPO / "deploy").parts)
                          for p in (REPO / "deploy").glob("*/**/__init__.py") if "build" not in p.parts}
    assert listed == found | {"deploy.embodiments"}


@pytest.mark.slow
def test_the_wheel_finds_its_configs_urdf_and_policies_and_trains_outside_the_checkout(tmp_path):
    src = tmp_path / "src"
    _copy(src, ["robot_hoi", "deploy", "sim2sim", "configs", "urdf", "policies", "setup.py", "pyproject.toml",
                "README.md"])
    (tmp_path / "dist").mkdir()
    wheel = _wheel(src, tmp_path / "dist")
    python = _venv(tmp_path / "venv")
    _pip(python, "install", "-q", "--no-compile", "torch==2.13.0", str(wheel), cwd=tmp_path)
    shutil.rmtree(src)  # nothing may fall back to the sources
    work = tmp_path / "elsewhere"
    work.mkdir()

    where = _run([str(python), "-c", "import json, robot_hoi.paths as p, deploy.embodiment as e; print(json.dumps("
                  "[str(p.CONFIGS_DIR), str(p.URDF_DIR), str(p.POLICIES_DIR), str(e.embodiment_search_dirs()[-1]),"
                  " str(p.REPO_ROOT)]))"], work, 120)
    assert where.returncode == 0, where.stderr
    *dirs, repo_root = json.loads(where.stdout)
    site = tmp_path / "venv" / "lib"
    for folder in dirs:
        assert Path(folder).is_dir() and Path(folder).is_relative_to(site), folder
    assert repo_root == "None"
    assert (Path(dirs[1]) / "g1_inspire.urdf").is_file()
    assert {"base_g1_inspire.pt", "lift_place_student.onnx"} <= {p.name for p in Path(dirs[2]).iterdir()}

    # teachers start from the shipped base policy, so this also reads policies/
    run = _run([str(tmp_path / "venv" / "bin" / "robot-hoi"), "train", "--budget", "2it", "--set", "env.num_envs=32",
                "--out", "runs/x"], work, 600)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    assert list((work / "runs" / "x").glob("*/model_2.pt"))


@pytest.mark.slow
def test_the_deploy_distribution_installs_alone_and_completes_a_dry_run(tmp_path):
    src = tmp_path / "src"
    _copy(src, ["deploy", "configs/embodiments"])
    (tmp_path / "dist").mkdir()
    wheel = _wheel(src / "deploy", tmp_path / "dist")
    python = _venv(tmp_path / "venv")  # no system site-packages: only what the distribution declares
    _pip(python, "install", "-q", "--no-compile", str(wheel), cwd=tmp_path)
    shutil.rmtree(src)
    work = tmp_path / "elsewhere"
    work.mkdir()

    absent = _run([str(python), "-c", "import importlib.util as u; "
                   "print([m for m in ('torch', 'mujoco', 'robot_hoi', 'sim2sim') if u.find_spec(m)])"], work, 60)
    assert absent.stdout.strip() == "[]", absent.stdout + absent.stderr

    policy = REPO / "policies" / "lift_place_student.onnx"  # the file a robot receives (its .motion.npz beside it)
    run = _run([str(tmp_path / "venv" / "bin" / "robot-hoi-deploy"), "--dry-run", "--policy", str(policy),
                "--duration", "4", "--auto-start", "--status", "off", "--log-dir", "log"], work, 300)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    summary = json.loads((work / "log" / "summary.json").read_text())
    assert summary["outcome"] == "COMPLETED" and summary["dry_run"] and summary["policy_steps"] > 0
