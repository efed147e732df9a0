"""deploy/ runs on the robot without torch, mujoco, scipy, onnx or robot_hoi: every module imports and a dry run
completes in a fresh interpreter where those imports raise ImportError."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

SCRIPT = textwrap.dedent('''
    import importlib, importlib.util, json, pkgutil, sys

    BLOCKED = {"torch", "mujoco", "robot_hoi", "scipy", "onnx", "trimesh", "matplotlib"}

    class Blocker:
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in BLOCKED:
                raise ImportError(f"{name} is blocked: deploy must not import it")
            return None

    sys.meta_path.insert(0, Blocker())
    import deploy

    has_dds = importlib.util.find_spec("cyclonedds") is not None
    imported = []
    for info in pkgutil.walk_packages(deploy.__path__, "deploy."):
        if info.name == "deploy.__main__" or (info.name == "deploy.body.unitree_idl" and not has_dds):
            continue
        importlib.import_module(info.name)
        imported.append(info.name)
    leaked = sorted(m for m in sys.modules if m.split(".")[0] in BLOCKED)
    from deploy.cli import main
    code = main(sys.argv[1:])
    print(json.dumps({"imported": imported, "leaked": leaked, "code": code}))
''')


def test_every_deploy_module_imports_and_dry_run_works_without_heavy_packages(dev_policy, tmp_path):
    argv = ["--dry-run", "--policy", str(dev_policy), "--duration", "2.0", "--log-dir", str(tmp_path),
            "--zero-torque-s", "0.1", "--ramp-s", "0.3", "--damp-s", "0.2", "--auto-start", "--hand-bus", "can",
            "--max-input-age-periods", "10", "--hand-timeout", "0.1", "--max-overruns", "1000",
            "--max-stall-periods", "30", "--watchdog-s", "2", "--min-hand-rate-share", "0.2"]
    proc = subprocess.run([sys.executable, "-c", SCRIPT, *argv], cwd=REPO, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["leaked"] == []
    assert result["code"] == 0
    expected = {"deploy.contract", "deploy.observations", "deploy.loop", "deploy.safety", "deploy.session",
                "deploy.cli", "deploy.body.simulated", "deploy.body.unitree_dds", "deploy.tracking_udp",
                "deploy.devpolicy", "deploy.hand_pair", "deploy.hands.simulated"}
    assert expected <= set(result["imported"])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["policy_steps"] > 0 and summary["faults"] == []


def test_python_dash_m_deploy_help():
    proc = subprocess.run([sys.executable, "-m", "deploy", "--help"], cwd=REPO, capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0 and "--dry-run" in proc.stdout and "--hand-port" in proc.stdout
