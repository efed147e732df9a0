"""What policies/ ships. The student: its ONNX follows today's deploy contract, it completes the interaction in
sim2sim (validation physics, self-collision on, simulated Inspire hands over serial bytes), and the robot runtime
runs it in a dry run without faults. The base policy (teachers' default start): it fits today's teacher network and
observation layout, and it walks. Policies are judged over many randomized starts with a margin below the measured
rate, never on one trajectory (whose outcome differs between CPUs)."""

from __future__ import annotations

import json

import pytest

from robot_hoi.paths import POLICIES_DIR

SHIPPED = POLICIES_DIR / "lift_place_student.onnx"
SKILLS = POLICIES_DIR / "multi_skill_student.onnx"
BASE = POLICIES_DIR / "base_g1_inspire.pt"

shipped_student = pytest.mark.skipif(not SHIPPED.is_file(), reason="no shipped student in policies/")
shipped_skills = pytest.mark.skipif(not SKILLS.is_file(), reason="no shipped multi-skill student in policies/")
shipped_base = pytest.mark.skipif(not BASE.is_file(), reason="no shipped base policy in policies/")


@shipped_student
def test_shipped_student_meets_the_contract_and_carries_its_reference():
    from robot_hoi.cli import main

    assert SHIPPED.with_name("lift_place_student.motion.npz").is_file()
    assert main(["export", "check", str(SHIPPED), "--embodiment", "g1_inspire"]) == 0


@shipped_student
@pytest.mark.slow
def test_shipped_student_lifts_the_box_in_sim2sim(tmp_path):
    from robot_hoi.cli import main

    # 32 of 32 sim2sim episodes (each from its own seeded spawn) completed it with interaction success (Wilson 95 %
    # interval 0.89-1.00; docs/results/README.md#shipped_student_sim2sim): 6 of 8 sits below that interval
    out = tmp_path / "report"
    assert main(["sim2sim", "--policy", str(SHIPPED), "--suite", "nominal", "--episodes", "8", "--videos", "0",
                 "-q", "-o", str(out)]) == 0
    cell = json.loads((out / "metrics.json").read_text())["cells"][0]
    assert cell["episodes"] == 8 and cell["success_rate"] >= 0.75 and cell["interaction_success_rate"] >= 0.75


def dry_run(policy, log_dir, *extra, duration=5.0) -> dict:
    """`robot-hoi deploy --dry-run` of `policy`: its summary, after asserting it exited cleanly without faults."""
    from deploy.cli import main as deploy_main

    code = deploy_main(["--dry-run", "--policy", str(policy), *extra, "--hand-bus", "serial",
                        "--duration", str(duration), "--log-dir", str(log_dir), "--zero-torque-s", "0.1",
                        "--ramp-s", "0.5", "--damp-s", "0.2", "--auto-start", "--max-input-age-periods", "10",
                        "--max-overruns", "1000", "--min-hand-rate-share", "0.2", "--status", "plain"])
    summary = json.loads((log_dir / "summary.json").read_text())
    assert code == 0 and summary["faults"] == []
    return summary


@shipped_student
def test_shipped_student_runs_on_the_dry_run_robot(tmp_path):
    summary = dry_run(SHIPPED, tmp_path)
    # ~3.8 s of POLICY at 30 Hz; a loaded machine skips deadlines (counted, not faults), the rest ran the policy
    assert summary["policy_steps"] + summary["missed_deadlines"] >= 100 and summary["policy_steps"] >= 60


def shipped_skills_contract():
    from deploy.contract import PolicyContract

    return PolicyContract.from_onnx(SKILLS)


@shipped_skills
def test_shipped_multi_skill_student_meets_the_contract_with_a_sidecar_per_skill():
    from robot_hoi.cli import main

    assert main(["export", "check", str(SKILLS), "--embodiment", "g1_inspire"]) == 0
    contract = shipped_skills_contract()
    assert len(contract.skills) >= 4
    for name in contract.skills:
        assert contract.skill_reference(name)[0].is_file(), name


@shipped_skills
@pytest.mark.slow
def test_shipped_multi_skill_student_completes_four_skills_in_sim2sim(tmp_path):
    from robot_hoi.cli import main

    # 16 of 16 sim2sim episodes each (Wilson 95 % interval 0.81-1.00; docs/results/README.md#multi_skill_student_sim2sim)
    # on these four; its walk seed1 and turns fall in sim2sim and are not asserted. 6 of 8 sits below that interval
    out = tmp_path / "report"
    main(["sim2sim", "--policy", str(SKILLS), "--suite", "nominal", "--episodes", "8", "--videos", "0", "-q",
          "-o", str(out)])  # NOT READY (its falling skills): the exit code says so; the cells are checked below
    cells = {c["clip"]: c for c in json.loads((out / "metrics.json").read_text())["cells"]}
    for clip in ("synth_lift_place_seed0", "synth_walk_seed2", "synth_squat_seed0", "synth_squat_seed1"):
        assert cells[clip]["episodes"] == 8 and cells[clip]["success_rate"] >= 0.75, clip


@shipped_skills
def test_every_skill_of_the_shipped_multi_skill_student_runs_on_the_dry_run_robot(tmp_path):
    for name in shipped_skills_contract().skills:
        summary = dry_run(SKILLS, tmp_path / name, "--skill", name, duration=2.5)
        assert summary["policy_steps"] + summary["missed_deadlines"] >= 25, name


@shipped_base
@pytest.mark.slow
def test_shipped_base_policy_walks_a_clip_from_randomized_starts(capsys):
    from robot_hoi.cli import main

    # the eval builds today's env and loads the weights: a layout or network drift fails here, not in a user's run.
    # Over 32 randomized starts (the default protocol) it walked embedded:walk:2 in 31 (0.97, Wilson 95 % interval
    # 0.84-0.99; docs/results/README.md#base_policy); the bound sits below that interval, so a different CPU's
    # chaotic trajectories pass and a broken policy (near 0) does not.
    assert main(["eval", str(BASE), "--data", "embedded:walk:2", "--episodes", "32", "--json"]) == 0
    walk = next(iter(json.loads(capsys.readouterr().out)["clips"].values()))["ours"]
    assert walk["success"]["n"] == 32 and walk["success"]["rate"] >= 0.7 and walk["E_h_cm"]["mean"] < 10.0


@shipped_base
def test_teachers_start_from_the_shipped_base_policy(tmp_path):
    from robot_hoi.cli import main
    from robot_hoi.rl.checkpoint import read_checkpoint, resolve_checkpoint

    out = tmp_path / "run"
    assert main(["train", "--budget", "1it", "--eval-episodes", "1", "--set", "env.num_envs=16",
                 "--set", "ppo.horizon=8", "--set", "runner.progress=false", "--out", str(out)]) == 0
    ours, base = read_checkpoint(resolve_checkpoint(out)), read_checkpoint(BASE)
    assert ours["iteration"] == 1 and base["dims"] == ours["dims"]
    name = "actor.0.weight"
    drift = (ours["model"][name] - base["model"][name]).abs().mean()
    assert drift < 0.05 * base["model"][name].abs().mean()  # one update away from the base, not a fresh network
    # ... and a small step: a fresh Adam moves every weight by the full learning rate. From the fast preset's former
    # 1e-4 the first update here is KL 0.94 (0.12 from 2e-5); on a 6144-sample table rollout 2.5 (0.024 from 2e-5)
    first = json.loads((resolve_checkpoint(out).parent / "scalars.jsonl").read_text().splitlines()[0])
    assert first["Policy/kl"] < 0.3
