"""Physics settings and perturbation suites: validation, what they write into the model, how suites resolve."""

from __future__ import annotations

import mujoco
import pytest

from robot_hoi.errors import UserError
from sim2sim.perturbations import ALL, NOMINAL, SUITES, Perturbation, resolve_suite
from sim2sim.physics import PhysicsSettings, differences, training_physics


def test_settings_validate_and_derive_the_pd_grid():
    assert PhysicsSettings().substeps == 1 and PhysicsSettings().pd_dt == pytest.approx(0.002)
    assert PhysicsSettings(timestep=0.001, pd_rate_hz=500).substeps == 2
    with pytest.raises(ValueError, match="whole number"):
        PhysicsSettings(timestep=0.002, pd_rate_hz=300)
    with pytest.raises(ValueError, match="integrator"):
        PhysicsSettings(integrator="verlet")
    with pytest.raises(ValueError, match="solver"):
        PhysicsSettings(solver="magic")


def test_apply_writes_the_options_and_differs_from_training():
    from robot_hoi.embodiment import build_model, load_embodiment

    training_model = build_model(load_embodiment("g1_inspire"))
    training = training_physics(training_model)
    assert training["integrator"] == "implicitfast"
    model = build_model(load_embodiment("g1_inspire"))
    PhysicsSettings(timestep=0.001, integrator="rk4", solver="cg", iterations=7, pd_rate_hz=1000).apply(model)
    assert model.opt.timestep == 0.001
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
    assert model.opt.solver == mujoco.mjtSolver.mjSOL_CG
    assert model.opt.iterations == 7
    diff = " ".join(differences(PhysicsSettings(), training))
    for word in ("timestep", "integrator", "iterations", "PD"):
        assert word in diff


def test_suites_resolve():
    default = [p.name for p in resolve_suite("default")]
    assert default[0] == "nominal" and "object_mass_x10" in default and len(default) >= 4
    robust = resolve_suite("robust")
    assert {p.name for p in robust} == set(ALL) and len(robust) > len(default)
    assert [p.name for p in resolve_suite("default", ["push_0.3", "physics_rk4_1ms"])] == ["push_0.3",
                                                                                          "physics_rk4_1ms"]
    with pytest.raises(UserError, match="unknown perturbation"):
        resolve_suite("default", ["mass_x1000"])
    with pytest.raises(UserError, match="--suite"):
        resolve_suite("everything")
    assert set(SUITES["default"]) <= set(ALL)


def test_hardware_suite_holds_what_the_robot_meets():
    hardware = {p.name: p for p in resolve_suite("hardware")}
    assert list(hardware)[0] == "nominal" and len(hardware) == 12
    changed = {name: p.changes() for name, p in hardware.items()}
    assert changed["object_mass_x0.5"] == {"object_mass_scale": 0.5} and changed["object_mass_x2"] == {
        "object_mass_scale": 2.0}
    assert changed["friction_x0.5"] == {"friction_scale": 0.5} and changed["friction_x1.5"] == {"friction_scale": 1.5}
    assert changed["actuator_latency_20ms"] == {"actuator_latency_s": 0.02}
    assert changed["pd_gains_x0.7"] == {"kp_scale": 0.7, "kd_scale": 0.7}
    assert changed["pd_gains_x1.3"] == {"kp_scale": 1.3, "kd_scale": 1.3}
    assert changed["tracker_latency_30ms"] == {"tracker_latency_s": 0.03}
    assert changed["push_0.6"] == {"push_dv": 0.6}
    assert {"joint_pos_noise", "gyro_noise", "tracker_rot_noise"} <= set(changed["sensor_noise"])
    assert len(changed["combined"]) > 3  # several at once


def test_changes_lists_only_what_differs():
    assert NOMINAL.changes() == {}
    assert ALL["object_mass_x10"].changes() == {"object_mass_scale": 10.0}
    assert set(ALL["sensor_noise"].changes()) >= {"joint_pos_noise", "imu_rot_noise", "tracker_pos_noise"}
    assert "physics" in ALL["physics_rk4_1ms"].changes()
    assert Perturbation("x", push_dv=0.5).to_dict()["push_interval_s"] == [2.0, 4.0]
