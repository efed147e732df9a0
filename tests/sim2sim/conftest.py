"""Fixtures for the sim2sim tests: a policy exported by the project, a standing policy with the same contract,
and the evaluation target (validation scene + reference) of the embedded clip. Built once per session."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from deploy.contract import PolicyContract


@pytest.fixture(scope="session")
def exported_policy(tmp_path_factory) -> Path:
    """`robot-hoi export onnx --untrained` output (policy + motion sidecar) for the embedded clip."""
    from robot_hoi.cli import main

    path = tmp_path_factory.mktemp("policies") / "untrained.onnx"
    assert main(["export", "onnx", "--untrained", "-o", str(path), "--recorded", "64"]) == 0
    assert path.with_name("untrained.motion.npz").is_file()
    return path


@pytest.fixture(scope="session")
def stand_policy(exported_policy) -> Path:
    """Same contract and sidecar, actions always 0 with fixed offsets: joint targets = the default pose."""
    import json

    import onnx

    from deploy.devpolicy import onnx_bytes

    contract = PolicyContract.from_onnx(exported_policy)
    metadata = {p.key: p.value for p in onnx.load(str(exported_policy)).metadata_props}
    metadata["action_offset_mode"] = json.dumps("fixed")
    path = exported_policy.with_name("stand.onnx")
    weights = np.zeros((contract.obs_dim, contract.num_actions), np.float32)
    path.write_bytes(onnx_bytes(metadata, weights, np.zeros(contract.num_actions, np.float32)))
    return path


@pytest.fixture(scope="session")
def contract(exported_policy) -> PolicyContract:
    return PolicyContract.from_onnx(exported_policy)


@pytest.fixture(scope="session")
def target(contract):
    from sim2sim.targets import policy_targets

    return policy_targets(contract, None, "g1_inspire", True)[0]


@pytest.fixture
def make_world(target, contract):
    """A fresh SimWorld of the validation scene, robot at the clip start in the gantry."""
    from sim2sim.episode import start_qpos
    from sim2sim.layout import WorldLayout
    from sim2sim.perturbations import NOMINAL
    from sim2sim.scene import load_model
    from sim2sim.world import SimWorld

    def make(perturbation=NOMINAL, seed: int = 0):
        model = load_model(target.scene)
        layout = WorldLayout.resolve(model, contract)
        world = SimWorld(model, layout, perturbation, np.random.default_rng(seed))
        world.reset(start_qpos(model, layout, target.motion, np.random.default_rng(seed)),
                    target.motion.object_pos[0], target.motion.object_quat_wxyz[0])
        return world

    return make


def run_cli(args: list[str], cwd: Path, timeout: float = 240.0):
    """`robot-hoi ...` in a fresh interpreter, in `cwd`, without the ../shared reference folder."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, ROBOT_HOI_SHARED=str(cwd / "no-shared-here"), PYTHONPATH=str(REPO))
    return subprocess.run([sys.executable, "-m", "robot_hoi.cli", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout)


REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def cli():
    return run_cli


@pytest.fixture(scope="session")
def e2e_report(exported_policy, tmp_path_factory) -> Path:
    """The default suite on the embedded clip with the exported policy: short episodes, one video."""
    cwd = tmp_path_factory.mktemp("e2e")
    result = run_cli(["sim2sim", "--policy", str(exported_policy), "-o", "report", "--seconds", "1.5",
                      "--episodes", "1", "--videos", "1", "--workers", "2"], cwd)
    assert result.returncode == 0, result.stdout + result.stderr
    return cwd / "report"
