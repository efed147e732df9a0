"""Imports sit at the top of a module. A function-local import in the library (robot_hoi/ but its commands,
sim2sim/, deploy/) must be listed in ALLOWED below with its reason: an optional dependency, an import cycle, an
order it must follow (MuJoCo's GL backend, matplotlib's Agg backend), or a measured start-up cost. Pure ast: the
check imports nothing.

The command modules (robot_hoi/commands/, robot_hoi/cli.py, sim2sim/cli.py, deploy/cli.py) import lazily on
purpose, so `robot-hoi --help` answers without torch or MuJoCo (robot_hoi/commands/__init__.py has the figures);
the last test keeps that true."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("robot_hoi", "sim2sim", "deploy")
COMMAND_MODULES = ("robot_hoi/commands/", "robot_hoi/cli.py", "sim2sim/cli.py", "deploy/cli.py",
                   "deploy/__main__.py")

OPTIONAL_RAY = "optional: the cluster extra"
OPTIONAL_DDS = "optional: cyclonedds (the deploy-dds extra); the body imports without it"
TRANSPORT = "a hand transport's library (pyserial, pymodbus, python-can) loads only when that bus is opened"
GL = "mujoco reads MUJOCO_GL when first imported: only after choose_gl_backend"
AGG = "pyplot (~0.5 s) only to draw, after matplotlib.use('Agg')"
HELP = "`robot-hoi --help` imports this module (a command builds its parser from it)"
WORKERS = "sim2sim's episode workers import this module: the training stack (torch) stays out of them"

# module -> {imported module: why it is imported inside a function}
ALLOWED: dict[str, dict[str, str]] = {
    "robot_hoi.data.clip": {"robot_hoi.data.readers": "cycle: readers builds its HOIClips from clip"},
    "robot_hoi.data.objects": {
        "coacd": "with coacd's library loaded first, importing onnxruntime segfaults (unless torch came first)"},
    "robot_hoi.embodiment.clip_view": {"matplotlib": AGG, "matplotlib.pyplot": AGG},
    "robot_hoi.embodiment.render": {"mujoco": GL, "mujoco.viewer": "GLFW: only with a display",
                                    "robot_hoi.embodiment.mjcf": GL},
    "robot_hoi.retarget.video": {"mujoco": GL, "robot_hoi.embodiment": GL, "robot_hoi.sim.video": GL,
                                 "matplotlib": AGG, "matplotlib.pyplot": AGG},
    "robot_hoi.rl.cluster": {"ray": OPTIONAL_RAY, "ray.util.scheduling_strategies": OPTIONAL_RAY},
    "robot_hoi.rl.evaluation": {"torch": HELP, "robot_hoi.sim.device": HELP + "; it imports torch",
                                "scipy.stats": "~0.5 s to import; " + HELP},
    "robot_hoi.rl.logger": {"torch.utils.tensorboard": "~0.3 s beyond torch, only when TensorBoard is wanted"},
    "robot_hoi.sim.backend": {"robot_hoi.sim.mujoco_cpu": "cycle: the backends subclass PhysicsBackend",
                              "robot_hoi.sim.warp_backend": "cycle: the backends subclass PhysicsBackend"},
    "robot_hoi.sim.device": {"warp": "optional: the warp extra", "mujoco_warp": "optional: the warp extra"},
    "robot_hoi.tasks.interaction.env_cfg": {
        "robot_hoi.data.objects": "trimesh and scipy (~0.7 s); " + HELP,
        "robot_hoi.retarget.executable": "the retarget imports MuJoCo; " + HELP,
        "robot_hoi.retarget.hands": "the retarget imports MuJoCo; " + HELP,
        "robot_hoi.retarget.ik": "the retarget imports MuJoCo; " + HELP,
        "robot_hoi.retarget.targets": "the retarget imports MuJoCo; " + HELP},
    "sim2sim.scene": {"robot_hoi.sim.scene": WORKERS},
    "sim2sim.targets": {"robot_hoi.export.motion_sidecar": WORKERS,
                        "robot_hoi.tasks.interaction.env_cfg": WORKERS,
                        "robot_hoi.tasks.interaction.factory": WORKERS,
                        "robot_hoi.tasks.interaction.reference": WORKERS},
    "sim2sim.video": {"robot_hoi.sim.video": "the render process sets MUJOCO_GL first",
                      "sim2sim.scene": "the render process sets MUJOCO_GL first"},
    "deploy.body.dds_loopback": {m: OPTIONAL_DDS for m in ("cyclonedds.domain", "cyclonedds.pub",
                                                         "cyclonedds.topic")},
    "deploy.body.unitree_dds": {
        "deploy.body": OPTIONAL_DDS + " (unitree_idl)",
        **{m: OPTIONAL_DDS for m in ("cyclonedds.idl", "cyclonedds.core", "cyclonedds.domain", "cyclonedds.pub",
                                     "cyclonedds.qos", "cyclonedds.sub", "cyclonedds.topic", "cyclonedds.util")}},
    "deploy.contract": {"deploy.policy": "cycle: policy builds on contract"},
    "deploy.devpolicy": {"onnx": "optional: not in the robot's install (deploy/pyproject.toml)"},
    "deploy.hands": {m: TRANSPORT for m in ("deploy.hands.serial_bus", "deploy.hands.modbus_bus",
                                           "deploy.hands.can_bus")},
    "deploy.hands.simulated": {m: TRANSPORT for m in ("deploy.hands.sim_serial", "deploy.hands.sim_can")},
    "deploy.watchdog": {"cyclonedds.pub": OPTIONAL_DDS, "cyclonedds.topic": OPTIONAL_DDS},
}


def _library_files() -> list[Path]:
    files = []
    for package in PACKAGES:
        for path in sorted((REPO / package).rglob("*.py")):
            rel = path.relative_to(REPO).as_posix()
            if not rel.startswith(COMMAND_MODULES):
                files.append(path)
    return files


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _local_imports(path: Path) -> list[tuple[int, str]]:
    """(line, imported module) of each import statement inside a function."""
    found = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if in_function and isinstance(child, ast.Import):
                found.extend((child.lineno, alias.name) for alias in child.names)
            elif in_function and isinstance(child, ast.ImportFrom):
                found.append((child.lineno, "." * child.level + (child.module or "")))
            visit(child, in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)))

    visit(ast.parse(path.read_text(encoding="utf-8"), filename=str(path)), False)
    return found


def test_function_local_imports_are_justified():
    unlisted, used = [], set()
    for path in _library_files():
        module = _module_name(path)
        for line, imported in _local_imports(path):
            if imported in ALLOWED.get(module, {}):
                used.add((module, imported))
            else:
                unlisted.append(f"{path.relative_to(REPO)}:{line}: {imported}")
    assert not unlisted, ("imports inside functions: move them to the top of the module, or list them in "
                          "tests/test_imports.py ALLOWED with the reason\n" + "\n".join(unlisted))
    stale = sorted(f"{m} -> {i}" for m, names in ALLOWED.items() for i in names if (m, i) not in used)
    assert not stale, "ALLOWED names imports no function makes any more: " + ", ".join(stale)


def test_the_check_sees_imports_in_methods_and_nested_functions(tmp_path):
    path = tmp_path / "example.py"
    path.write_text("import os\n\nclass A:\n    def f(self):\n        import json\n\n"
                    "        def g():\n            from pathlib import Path\n")
    assert _local_imports(path) == [(5, "json"), (8, "pathlib")]


def test_help_imports_neither_torch_nor_mujoco():
    """What the command modules' lazy imports are for."""
    code = ("import contextlib, io, sys\nfrom robot_hoi import cli\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try:\n        cli.main(['--help'])\n    except SystemExit:\n        pass\n"
            "print(sorted(m for m in ('torch', 'mujoco', 'scipy', 'onnxruntime') if m in sys.modules))\n")
    result = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    assert result.stdout.strip().splitlines()[-1] == "[]"
