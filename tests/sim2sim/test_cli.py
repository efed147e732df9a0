"""`robot-hoi sim2sim` end to end on a fresh checkout's data: the embedded clip, a policy exported by the
project, the default suite, every report file; comparison mode; user errors."""

from __future__ import annotations

import json
import math

import pytest

from sim2sim.perturbations import SUITES

METRICS = ("E_h_cm", "E_o_cm", "mpjpe_g_mm", "mpjpe_mm", "e_acc_mm", "e_vel_mm", "duration_s")


@pytest.mark.slow
def test_report_for_the_embedded_clip(e2e_report, exported_policy):
    data = json.loads((e2e_report / "metrics.json").read_text())
    assert data["format"] == "robot-hoi sim2sim report"
    assert [p["name"] for p in data["perturbations"]] == list(SUITES["default"])
    assert [c["perturbation"] for c in data["cells"]] == list(SUITES["default"])
    assert data["clips"][0]["name"].startswith("synth_lift_place")
    assert data["policies"][0]["path"] == str(exported_policy) and len(data["policies"][0]["sha256"]) == 64
    assert any("integrator" in d for d in data["physics"]["differences"])
    for cell in data["cells"]:
        assert cell["episodes"] == 1 and cell["errors"] == []
        assert 0.0 <= cell["success_rate"] <= 1.0
        assert 0.0 <= cell["interaction_success_rate"] <= cell["success_rate"]
        for key in METRICS:
            assert cell[key]["n"] == 1 and math.isfinite(cell[key]["mean"]), (cell["perturbation"], key)
        assert cell["hand_bus"]["cycles"] > 0
        assert cell["timing"]["policy_tick_wall_ms_p50"]["mean"] > 0
    episodes = data["episodes"]
    for e in episodes:  # judged on the worst tracked frame, as in training
        assert isinstance(e["interaction_success"], bool) and e["E_o_max_cm"] >= e["E_o_cm"] > 0
        assert e["interaction_success"] <= e["success"]
    assert len(episodes) == len(SUITES["default"]) and all("trace" not in e for e in episodes)
    assert data["timing"]["simulated_s"] > 0 and data["timing"]["realtime_factor_per_core"] > 0

    summary = (e2e_report / "summary.md").read_text()
    for name in SUITES["default"]:
        assert f"| {name} |" in summary
    html = (e2e_report / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 4
    if data["videos"]:
        video = e2e_report / data["videos"][0]["file"]
        assert video.is_file() and video.stat().st_size > 10_000
        assert data["videos"][0]["file"] in html
    else:  # no GL backend on this machine: the report says why and keeps its plots
        assert "no OpenGL backend" in data["render"]["message"]


@pytest.mark.slow
def test_compare_with_a_previous_run_and_a_second_policy(e2e_report, exported_policy, stand_policy, cli, tmp_path):
    result = cli(["sim2sim", "--policy", str(stand_policy), "--compare", str(e2e_report), "-o", "cmp", "--seconds",
                  "0.5", "--episodes", "1", "--videos", "0", "--perturbations", "nominal", "-q"], tmp_path)
    assert result.returncode == 0, result.stderr
    data = json.loads((tmp_path / "cmp" / "metrics.json").read_text())
    labels = [p["label"] for p in data["policies"]]
    assert labels == ["stand", "untrained"] and data["policies"][1]["origin"].startswith("previous run")
    assert {c["policy"] for c in data["cells"] if c["perturbation"] == "nominal"} == {"stand", "untrained"}
    assert "| nominal |" in (tmp_path / "cmp" / "summary.md").read_text()
    assert " / " in (tmp_path / "cmp" / "summary.md").read_text()  # side by side

    result = cli(["sim2sim", "--policy", str(stand_policy), "--compare", str(exported_policy), "-o", "two",
                  "--seconds", "0.5", "--episodes", "1", "--videos", "0", "--perturbations", "nominal", "-q",
                  "--workers", "1"], tmp_path)
    assert result.returncode == 0, result.stderr
    data = json.loads((tmp_path / "two" / "metrics.json").read_text())
    assert [p["origin"] for p in data["policies"]] == ["evaluated here"] * 2
    assert len(data["episodes"]) == 2


@pytest.mark.slow
def test_user_errors_are_one_line(cli, tmp_path, exported_policy):
    cases = [
        (["sim2sim", "--policy", "missing.onnx"], "missing.onnx: policy file not found"),
        (["sim2sim", "--policy", str(exported_policy), "--perturbations", "mass_x1000"], "unknown perturbation"),
        (["sim2sim", "--policy", str(exported_policy), "--compare", "nowhere/"], "no metrics.json"),
        (["sim2sim", "--policy", str(exported_policy), "--episodes", "0"], "--episodes must be >= 1"),
        (["sim2sim", "--policy", str(exported_policy), "--hand-bus", "can", "--hand-link", "direct"],
         "--hand-link direct"),
    ]
    for args, message in cases:
        result = cli(args, tmp_path)
        assert result.returncode == 2, (args, result.stderr)
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("robot-hoi sim2sim: error:"), result.stderr
        assert message in lines[0]


def test_min_success_gate_and_crashed_episodes_set_the_exit_code(monkeypatch, tmp_path, capsys):
    import argparse

    import sim2sim.evaluate as evaluate_module
    from sim2sim import cli as sim2sim_cli

    def fake_report(rate, errors=()):
        cell = {"policy": "A", "clip": "c", "perturbation": "nominal", "success_rate": rate, "errors": list(errors),
                "E_h_cm": {"mean": 3.0}}
        timing = {"simulated_s": 1.0, "wall_s": 1.0, "workers": 1, "realtime_factor_per_episode": 1.0,
                  "realtime_factor_per_cpu_second": 1.0}
        report = {"policies": [{"label": "A"}], "cells": [cell], "videos": [], "timing": timing}
        return report, {"html": tmp_path / "r.html", "metrics": tmp_path / "m.json", "summary": tmp_path / "s.md"}

    parser = argparse.ArgumentParser()
    sim2sim_cli.register(parser.add_subparsers())
    args = parser.parse_args(["sim2sim", "--policy", "p.onnx", "--min-success", "0.8"])
    for rate, errors, code in ((0.9, (), 0), (0.5, (), 1), (1.0, ("RuntimeError: boom",), 1)):
        monkeypatch.setattr(evaluate_module, "evaluate", lambda options, r=rate, e=errors: fake_report(r, e))
        assert args.func(args) == code, (rate, errors)
    assert "crashed" in capsys.readouterr().err


def test_the_hardware_suite_runs_16_episodes_per_condition_unless_told(monkeypatch):
    import argparse

    import sim2sim.evaluate as evaluate_module
    from sim2sim import cli as sim2sim_cli

    seen = []

    def capture(options):
        seen.append(options.episodes)
        raise SystemExit(0)

    monkeypatch.setattr(evaluate_module, "evaluate", capture)
    parser = argparse.ArgumentParser()
    sim2sim_cli.register(parser.add_subparsers())
    for argv in (["--suite", "hardware"], ["--suite", "hardware", "--episodes", "20"], ["--suite", "robust"],
                 ["--suite", "hardware", "--perturbations", "push_0.6"]):
        args = parser.parse_args(["sim2sim", "--policy", "p.onnx", *argv])
        with pytest.raises(SystemExit):
            args.func(args)
    assert seen == [16, 20, 3, 3]
