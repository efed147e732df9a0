"""The report answers "can this run on the robot?": verdict, definitions, honest plots and rows."""

from __future__ import annotations

import numpy as np

from sim2sim.episode import fell
from sim2sim.plots import metric_bars
from sim2sim.report import html_page, markdown
from sim2sim.tables import result_tables
from sim2sim.verdict import ReadyThresholds, verdict, verdict_lines


def _cell(perturbation, success, e_h=5.0, touched=1, pushes=0, fell_episodes=0, faults=0):
    stat = lambda v: {"mean": v, "std": 0.0, "n": 1}  # noqa: E731
    return {"policy": "A", "clip": "box", "perturbation": perturbation, "episodes": 1, "errors": [],
            "success_rate": success, "outcomes": {"terminated: link_deviation (fell: pelvis at 0.12 m)": 1},
            "duration_s": stat(1.0), "E_h_cm": stat(e_h), "E_o_cm": stat(0.8), "mpjpe_g_mm": stat(50.0),
            "mpjpe_mm": stat(40.0), "e_acc_mm": stat(1.0), "e_vel_mm": stat(2.0),
            "hand": {}, "hand_bus": {}, "touched_episodes": touched, "fell_episodes": fell_episodes,
            "pushes_applied": pushes, "runtime": {"episodes_with_faults": faults},
            "timing": {"policy_tick_wall_ms_p99": stat(1.5)}}


def _report(cells):
    return {"policies": [{"label": "A", "path": "a.onnx", "control_dt": 0.02}],
            "perturbations": [{"name": "nominal", "description": "", "changes": {}},
                              {"name": "push_0.3", "description": "", "changes": {"push_dv": 0.3}}],
            "cells": cells}


def test_not_ready_names_the_thresholds_and_how_to_change_them():
    report = _report([_cell("nominal", 0.0, e_h=30.0, touched=0, fell_episodes=1), _cell("push_0.3", 0.0)])
    v = verdict(report, ReadyThresholds(min_success=0.8, max_e_h_cm=10.0))
    lines = verdict_lines(v)
    assert not v["ready"] and lines[0].startswith("NOT READY")
    assert any("success 0.00 (needs >= 0.8, --ready-success RATE)" in line for line in lines)
    assert any("E_h 30.0 cm (needs <= 10 cm, --ready-e-h CM)" in line for line in lines)
    assert any("fell in 1 of 1" in line for line in lines) and "--ready-e-h" in lines[-1]


def test_ready_when_every_threshold_holds():
    v = verdict(_report([_cell("nominal", 1.0), _cell("push_0.3", 1.0, pushes=2)]))
    assert v["ready"] and verdict_lines(v)[0].startswith("READY")


def test_reaching_the_end_without_the_object_is_not_ready():
    cell = _cell("nominal", 1.0)
    cell["interaction_success_rate"] = 0.25
    v = verdict(_report([cell]))
    lines = verdict_lines(v)
    assert not v["ready"]
    assert any("interaction success 0.25 (needs >= 0.8" in line for line in lines)
    table = result_tables(_report([cell]))[0]
    assert table.rows[0][table.headers.index("interaction success")] == "0.25"
    assert "interaction success:" in table.note


def _hardware_report(success_by_condition, episodes=16):
    from sim2sim.perturbations import SUITES

    cells = []
    for name in SUITES["hardware"]:
        cell = _cell(name, success_by_condition.get(name, 1.0))
        # nominal gates interaction success too; the perturbed conditions report it beside success
        cell["episodes"], cell["interaction_success_rate"] = episodes, 1.0 if name == "nominal" else 0.5
        cells.append(cell)
    report = _report(cells)
    report["suite"] = "hardware"
    report["perturbations"] = [{"name": n, "description": "", "changes": {}} for n in SUITES["hardware"]]
    return report


def test_hardware_suite_is_ready_only_when_every_condition_succeeds_over_16_episodes():
    v = verdict(_hardware_report({}))
    assert v["ready"] and verdict_lines(v)[0].startswith("READY: A meets every threshold in every condition of the "
                                                         "hardware suite")
    assert sum("over 16 episodes (interaction 0.50)" in line for _, line in v["checks"]) == 11  # reported beside
    # one condition below the threshold: not ready, and the line names it
    v = verdict(_hardware_report({"push_0.6": 0.75}))
    lines = verdict_lines(v)
    assert not v["ready"] and lines[0].startswith("NOT READY: A misses 1 threshold(s) in every condition")
    assert lines[1] == ("box push_0.6: success 0.75 over 16 episodes (interaction 0.50) (needs >= 0.8 over >= 16 "
                        "episodes, --ready-success RATE, --episodes N)")
    # too few episodes: not ready, however well they went
    v = verdict(_hardware_report({}, episodes=8))
    assert not v["ready"] and sum(not ok for ok, _ in v["checks"]) == 12
    # a condition missing from the report fails
    report = _hardware_report({})
    report["cells"] = [c for c in report["cells"] if c["perturbation"] != "combined"]
    v = verdict(report)
    assert not v["ready"] and any(line == "box combined: not evaluated" for ok, line in v["checks"] if not ok)
    # other suites keep judging the nominal condition only
    report = _hardware_report({"push_0.6": 0.0})
    report["suite"] = "robust"
    assert verdict(report)["ready"]


def test_tables_define_metrics_mark_untouched_objects_and_unapplied_pushes():
    report = _report([_cell("nominal", 0.0, touched=0), _cell("push_0.3", 0.0, pushes=0)])
    table = result_tables(report)[0]
    rows = {row[0]: row for row in table.rows}
    assert "push_0.3 (not applied: every episode ended before the first push)" in rows
    e_o = table.headers.index("E_o (cm)")
    assert rows["nominal"][e_o] == "0.80 (never touched)"
    for term in ("E_h (cm):", "E_o (cm):", "g-MPJPE (mm):", "E_acc", "E_vel", "success:"):
        assert term in table.note


def test_verdict_heads_both_reports(monkeypatch):
    from sim2sim import report as report_module

    monkeypatch.setattr(report_module, "_overview", lambda report: [])  # run facts a real report carries
    report = _report([_cell("nominal", 0.0)])
    report["verdict"] = verdict(report)
    assert markdown(report).split("\n")[2].startswith("**NOT READY")
    page = html_page(report, [])
    assert page.index("id='verdict'") < page.index("<h3>")


def test_zero_success_plot_says_no_successes(monkeypatch):
    import matplotlib.axes

    texts = []
    original = matplotlib.axes.Axes.text
    monkeypatch.setattr(matplotlib.axes.Axes, "text", lambda self, *a, **k: texts.append(a[2]) or original(self, *a, **k))
    png = metric_bars([_cell("nominal", 0.0)], ("success_rate", "E_h_cm"), ["nominal"])
    assert png[:4] == b"\x89PNG" and texts == ["no successes"]


def test_fall_is_read_from_tilt_or_height():
    upright = np.array([0, 0, 0.75, 1.0, 0, 0, 0])
    squat = np.array([0, 0, 0.3, 1.0, 0, 0, 0])
    lying = np.array([0, 0, 0.25, np.cos(np.pi / 4), np.sin(np.pi / 4), 0, 0])  # 90 deg about x
    assert fell(upright) is None and fell(squat) is None
    assert fell(lying).startswith("fell: pelvis at 0.25 m, tilted 90 deg")
