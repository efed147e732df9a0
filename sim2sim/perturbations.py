"""Perturbations of the validation world and the suites that group them.

A Perturbation changes one thing about the world the runtime meets (or a few, for "combined"); every field's
neutral value leaves the nominal world unchanged. `--suite default` = nominal + a few that catch the usual
sim-to-real gaps; `--suite robust` = the full grid; `--suite hardware` = what a policy for the robot must survive,
judged condition by condition (sim2sim.verdict: every one at the success threshold over 16+ episodes).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

from robot_hoi.errors import UserError
from sim2sim.physics import PhysicsSettings

NOMINAL_PHYSICS = PhysicsSettings()


@dataclass(frozen=True)
class Perturbation:
    name: str
    description: str = "nominal world"
    physics: PhysicsSettings = field(default_factory=PhysicsSettings)
    friction_scale: float = 1.0  # floor and object sliding friction
    object_mass_scale: float = 1.0  # object mass and inertia
    actuator_latency_s: float = 0.0  # a LowCmd reaches the motor drivers this much later
    kp_scale: float = 1.0  # motor-driver gains actually applied / gains commanded
    kd_scale: float = 1.0
    joint_pos_noise: float = 0.0  # rad, std of each LowState q reading
    joint_vel_noise: float = 0.0  # rad/s
    imu_rot_noise: float = 0.0  # rad, std of an IMU orientation error (random axis)
    gyro_noise: float = 0.0  # rad/s
    tracker_latency_s: float = 0.0  # mocap poses arrive this late (stamped with their capture time)
    tracker_pos_noise: float = 0.0  # m
    tracker_rot_noise: float = 0.0  # rad
    push_dv: float = 0.0  # m/s horizontal velocity change of each push on the pelvis (0 = no pushes)
    push_interval_s: tuple[float, float] = (2.0, 4.0)  # time between pushes, uniform
    push_duration_s: float = 0.1

    def to_dict(self) -> dict:
        out = asdict(self)
        out["push_interval_s"] = list(self.push_interval_s)
        return out

    def changes(self) -> dict:
        """Only the fields that differ from the nominal world (for tables)."""
        nominal = Perturbation("nominal").to_dict()
        return {k: v for k, v in self.to_dict().items() if k not in ("name", "description") and v != nominal[k]}


def _p(name: str, description: str, **changes) -> Perturbation:
    return Perturbation(name=name, description=description, **changes)


NOMINAL = _p("nominal", "validation physics (differs from training), no perturbation")
SENSOR_NOISE = dict(joint_pos_noise=0.01, joint_vel_noise=0.2, imu_rot_noise=0.01, gyro_noise=0.05,
                    tracker_pos_noise=0.005, tracker_rot_noise=0.01)

ALL: dict[str, Perturbation] = {p.name: p for p in (
    NOMINAL,
    _p("physics_rk4_1ms", "RK4 integrator, Newton solver, 1 ms step, PD at 1 kHz",
       physics=PhysicsSettings(timestep=0.001, integrator="rk4", solver="newton", iterations=30,
                               pd_rate_hz=1000.0)),
    _p("physics_cg", "CG solver (50 iterations)", physics=PhysicsSettings(solver="cg", iterations=50)),
    _p("physics_elliptic", "elliptic friction cones, PGS solver",
       physics=PhysicsSettings(solver="pgs", cone="elliptic", iterations=50)),
    _p("friction_x0.5", "floor and object friction x0.5", friction_scale=0.5),
    _p("friction_x1.5", "floor and object friction x1.5", friction_scale=1.5),
    _p("object_mass_x0.5", "object mass x0.5", object_mass_scale=0.5),
    _p("object_mass_x2", "object mass x2", object_mass_scale=2.0),
    _p("object_mass_x5", "object mass x5", object_mass_scale=5.0),
    _p("object_mass_x10", "object mass x10", object_mass_scale=10.0),
    _p("actuator_latency_10ms", "LowCmd applied 10 ms late", actuator_latency_s=0.010),
    _p("actuator_latency_20ms", "LowCmd applied 20 ms late", actuator_latency_s=0.020),
    _p("actuator_latency_40ms", "LowCmd applied 40 ms late", actuator_latency_s=0.040),
    _p("sensor_noise", "joint, IMU and mocap noise", **SENSOR_NOISE),
    _p("tracker_latency_30ms", "mocap poses 30 ms late", tracker_latency_s=0.030),
    _p("pd_gains_x0.7", "motor drivers apply 0.7 x the commanded kp and kd", kp_scale=0.7, kd_scale=0.7),
    _p("pd_gains_x1.3", "motor drivers apply 1.3 x the commanded kp and kd", kp_scale=1.3, kd_scale=1.3),
    _p("push_0.3", "0.3 m/s pushes on the pelvis every 2-4 s", push_dv=0.3),
    _p("push_0.6", "0.6 m/s pushes on the pelvis every 2-4 s", push_dv=0.6),
    _p("combined", "mass x2, 20 ms latency, sensor noise, 0.3 m/s pushes", object_mass_scale=2.0,
       actuator_latency_s=0.020, push_dv=0.3, **SENSOR_NOISE),
)}

SUITES: dict[str, tuple[str, ...]] = {
    "default": ("nominal", "object_mass_x10", "actuator_latency_20ms", "sensor_noise", "push_0.3"),
    "robust": tuple(ALL),
    "nominal": ("nominal",),
    # what the robot meets: the object's mass and the friction it finds, motor-driver latency and gain mismatch,
    # sensor noise, mocap latency, pushes, and several at once (configs/recipes/hardware.yaml trains for them)
    "hardware": ("nominal", "object_mass_x0.5", "object_mass_x2", "friction_x0.5", "friction_x1.5",
                 "actuator_latency_20ms", "pd_gains_x0.7", "pd_gains_x1.3", "sensor_noise", "tracker_latency_30ms",
                 "push_0.6", "combined"),
}
# Suites whose verdict judges every condition (not only nominal), each over at least ReadyThresholds.min_episodes
EVERY_CONDITION_SUITES = ("hardware",)


def resolve_suite(suite: str, only: list[str] | None = None) -> list[Perturbation]:
    """The perturbations of a suite (optionally only the named ones, which may come from any suite)."""
    if only:
        unknown = [n for n in only if n not in ALL]
        if unknown:
            raise UserError(f"unknown perturbation(s) {', '.join(unknown)}; known: {', '.join(ALL)}")
        return [ALL[n] for n in only]
    if suite not in SUITES:
        raise UserError(f"--suite must be one of {', '.join(SUITES)}, got {suite!r}")
    return [ALL[n] for n in SUITES[suite]]


def with_physics(perturbation: Perturbation, physics: PhysicsSettings) -> Perturbation:
    return replace(perturbation, physics=physics)
