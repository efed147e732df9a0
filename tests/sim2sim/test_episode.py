"""Whole episodes: deploy's runtime through all its phases against the simulated robot, ended by the monitor."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from deploy.safety import Phase
from sim2sim.episode import EpisodeJob, run_episode
from sim2sim.monitor import Thresholds
from sim2sim.perturbations import NOMINAL


def _job(policy, target, **kw):
    kw.setdefault("max_frames", 20)
    return EpisodeJob(str(policy), "stand", target, kw.pop("perturbation", NOMINAL), 0, 7, **kw)


def test_standing_policy_runs_the_runtime_through_every_phase(stand_policy, target, contract):
    r = run_episode(_job(stand_policy, target))
    assert "error" not in r
    phases = r["runtime"]["phase_time_s"]
    for name in ("ZERO_TORQUE", "RAMP_TO_DEFAULT", "HOLD", "POLICY", "DAMP"):
        assert phases.get(name, 0) > 0, name
    assert r["runtime"]["faults"] == [] and r["runtime"]["final_phase"] == "DAMP"
    assert r["runtime"]["exit_reason"].startswith("operator stop")  # the monitor ended it at the clip's end
    assert r["success"] and r["outcome"] == "reached the end of the clip"
    warmup = contract.warmup_frames
    assert r["evaluated_frames"] == 20 + warmup  # ticks 1 .. f(t) = 20
    assert r["duration_s"] == pytest.approx((20 + warmup) / 30.0)
    for key in ("E_h_cm", "E_o_cm", "mpjpe_g_mm", "mpjpe_mm", "e_acc_mm", "e_vel_mm"):
        assert np.isfinite(r[key]) and r[key] >= 0, key
    trace = r["trace"]
    in_policy = trace["phase"] == Phase.POLICY
    assert in_policy.any() and np.all(trace["qpos"][in_policy, 2] > 0.7)  # stood on its own, off the gantry
    bus = r["hand"]["bus"]
    assert bus["left"]["cycles"] > 20 and bus["left"]["link_errors"] == 0 and bus["right"]["link_errors"] == 0
    assert r["hand"]["open_fraction"] > 0.5  # default pose: fingers open
    assert 0 < r["timing"]["sim_s"] and r["timing"]["realtime_factor"] > 0
    assert r["timing"]["torque_saturated_fraction"] < 0.05  # standing needs far less than the effort limits


def test_episodes_are_reproducible(stand_policy, target):
    a = run_episode(_job(stand_policy, target, max_frames=5))
    b = run_episode(_job(stand_policy, target, max_frames=5))
    assert a["E_h_cm"] == b["E_h_cm"]
    np.testing.assert_array_equal(a["trace"]["qpos"], b["trace"]["qpos"])


def test_early_termination_ends_the_episode(stand_policy, target):
    strict = replace(Thresholds(), max_mean_link_error=1e-4)
    r = run_episode(_job(stand_policy, target, thresholds=strict))
    assert not r["success"] and r["terminations"] == ["link_deviation"]
    assert r["evaluated_frames"] == 1 and r["outcome"] == "terminated: link_deviation"
    assert r["runtime"]["phase_time_s"]["POLICY"] < 0.2  # stopped through DAMP right away


def test_a_fall_is_a_failure(stand_policy, target):
    # the drivers apply 5 % of the gains: the stand collapses once the gantry lets go
    weak = replace(NOMINAL, kp_scale=0.05, kd_scale=0.05)
    r = run_episode(_job(stand_policy, target, perturbation=weak, max_frames=200))
    assert not r["success"]
    assert any(t in r["terminations"] for t in ("link_deviation", "root_too_low")) or r["runtime"]["faults"]


def test_stale_mocap_keeps_the_policy_from_starting(stand_policy, target):
    # poses older than two control periods: the runtime never leaves WAIT_STATE and gives up, nothing commanded
    late = replace(NOMINAL, tracker_latency_s=0.2)
    r = run_episode(_job(stand_policy, target, perturbation=late))
    assert not r["success"] and r["outcome"].startswith("policy never started")
    assert r["runtime"]["final_phase"] == "WAIT_STATE" and r["evaluated_frames"] == 0
    assert np.isnan(r["E_h_cm"]) and np.isnan(r["hand"]["mean_command"])
