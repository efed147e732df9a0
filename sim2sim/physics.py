"""Physics settings of the validation simulation, chosen to differ from training on purpose.

Training (robot_hoi/embodiment/mjcf.py) steps MuJoCo with the implicitfast integrator, the Newton solver at its
default 100 iterations and dt = control_dt / decimation (4.76 ms), and does the PD inside MuJoCo's position
actuators. The validator's nominal world uses the semi-implicit Euler integrator, a 2 ms step, the Newton
solver capped at 20 iterations (fast on this model; the robust suite adds CG, PGS with elliptic cones and RK4),
and the body PD is computed outside MuJoCo at the motor drivers' rate (500 Hz) from LowCmd-like targets, as
the robot's drivers do. A policy that only works with training's numerics fails here, not on the robot.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import mujoco

INTEGRATORS = ("euler", "rk4", "implicit", "implicitfast")
SOLVERS = ("pgs", "cg", "newton")
CONES = ("pyramidal", "elliptic")


@dataclass(frozen=True)
class PhysicsSettings:
    timestep: float = 0.002  # s
    integrator: str = "euler"
    solver: str = "newton"
    iterations: int = 20
    ls_iterations: int = 10
    cone: str = "pyramidal"
    pd_rate_hz: float = 500.0  # motor-driver PD update rate; a whole number of physics steps per update

    def __post_init__(self):
        if self.integrator not in INTEGRATORS:
            raise ValueError(f"integrator must be one of {INTEGRATORS}, got {self.integrator!r}")
        if self.solver not in SOLVERS:
            raise ValueError(f"solver must be one of {SOLVERS}, got {self.solver!r}")
        if self.cone not in CONES:
            raise ValueError(f"cone must be one of {CONES}, got {self.cone!r}")
        if not (self.timestep > 0 and self.pd_rate_hz > 0):
            raise ValueError("timestep and pd_rate_hz must be positive")
        steps = 1.0 / (self.pd_rate_hz * self.timestep)
        if steps < 1 - 1e-9 or not math.isclose(steps, round(steps), rel_tol=1e-6):
            raise ValueError(f"pd_rate_hz {self.pd_rate_hz} must be the physics rate {1 / self.timestep:g} Hz "
                             "divided by a whole number")

    @property
    def substeps(self) -> int:
        """Physics steps per PD update."""
        return int(round(1.0 / (self.pd_rate_hz * self.timestep)))

    @property
    def pd_dt(self) -> float:
        return self.substeps * self.timestep

    def apply(self, model) -> None:
        """Write the settings into a compiled mujoco.MjModel."""
        model.opt.timestep = self.timestep
        model.opt.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{self.integrator.upper()}")
        model.opt.solver = getattr(mujoco.mjtSolver, f"mjSOL_{self.solver.upper()}")
        model.opt.iterations = self.iterations
        model.opt.ls_iterations = self.ls_iterations
        model.opt.cone = getattr(mujoco.mjtCone, f"mjCONE_{self.cone.upper()}")

    def describe(self) -> str:
        return (f"{self.integrator}, {self.solver} x{self.iterations}, dt {self.timestep * 1e3:g} ms, "
                f"PD {self.pd_rate_hz:g} Hz ({self.cone} cones)")

    def to_dict(self) -> dict:
        return asdict(self)


def training_physics(model) -> dict:
    """What the training model (robot_hoi.embodiment.build_model) runs with, for the report's comparison."""
    opt = model.opt
    return {
        "timestep": float(opt.timestep),
        "integrator": mujoco.mjtIntegrator(opt.integrator).name[len("mjINT_"):].lower(),
        "solver": mujoco.mjtSolver(opt.solver).name[len("mjSOL_"):].lower(),
        "iterations": int(opt.iterations),
        "ls_iterations": int(opt.ls_iterations),
        "cone": mujoco.mjtCone(opt.cone).name[len("mjCONE_"):].lower(),
        "pd": "MuJoCo position actuators inside every physics step",
    }


def differences(settings: PhysicsSettings, training: dict) -> list[str]:
    """Human-readable list of what differs from training (empty: the validator would be a replay)."""
    out = []
    for key in ("timestep", "integrator", "solver", "iterations", "cone"):
        mine, theirs = getattr(settings, key), training.get(key)
        if theirs is not None and mine != theirs and not (key == "timestep" and math.isclose(mine, theirs)):
            out.append(f"{key}: {theirs} in training, {mine} here")
    out.append(f"PD: {training.get('pd', 'MuJoCo actuators')} in training, motor torques from LowCmd at "
               f"{settings.pd_rate_hz:g} Hz here")
    return out
