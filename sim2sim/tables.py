"""The report's tables, built once from metrics.json's content and rendered as Markdown and as HTML.

With two policies (or two runs) every cell shows "A / B" in the order the labels are listed.
"""

from __future__ import annotations

from dataclasses import dataclass

from sim2sim.summary import METRIC_KEYS, METRIC_LABELS, SUCCESS_KEYS, cell_value, definitions_note


@dataclass
class Table:
    title: str
    headers: list[str]
    rows: list[list[str]]
    note: str = ""


def fmt(value, digits: int = 2) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        if value != value:  # nan
            return "-"
        return f"{value:.{digits}f}"
    return str(value)


def _find(cells: list[dict], policy: str, clip: str, perturbation: str) -> dict | None:
    return next((c for c in cells if c["policy"] == policy and c["clip"] == clip
                 and c["perturbation"] == perturbation), None)


def _joined(cells, labels, clip, perturbation, getter, digits=2) -> str:
    values = []
    for label in labels:
        cell = _find(cells, label, clip, perturbation)
        values.append(fmt(getter(cell), digits) if cell is not None else "-")
    return " / ".join(values)


def _path(*keys: str, scale: float = 1.0):
    """Getter of a nested cell value (None when any level is missing, e.g. in an older metrics.json)."""

    def get(cell: dict):
        value = cell
        for key in keys:
            if not isinstance(value, dict) or key not in value:
                return None
            value = value[key]
        return None if value is None else scale * value

    return get


def _bus_problems(cell: dict) -> int:
    bus = cell.get("hand_bus", {})
    return bus.get("link_errors", 0) + bus.get("bus_retries", 0) + bus.get("late_cycles", 0)


def _e_o(cell: dict) -> str:
    """E_o with whether the object was touched at all (a robot that fell first leaves it where it started)."""
    value = fmt(cell_value(cell, "E_o_cm"))
    touched, episodes = cell.get("touched_episodes"), cell["episodes"] - len(cell["errors"])
    if touched is None or value == "-":
        return value
    return f"{value} (never touched)" if touched == 0 else value + ("" if touched == episodes else
                                                                  f" (touched {touched}/{episodes})")


def perturbation_label(report: dict, name: str) -> str:
    """The name, or 'name (not applied: ...)' for pushes no episode lived long enough to receive."""
    spec = next((p for p in report["perturbations"] if p["name"] == name), {})
    cells = [c for c in report["cells"] if c["perturbation"] == name]
    if spec.get("changes", {}).get("push_dv", 0) > 0 and cells and all(c.get("pushes_applied", 1) == 0
                                                                         for c in cells):
        return f"{name} (not applied: every episode ended before the first push)"
    return name


def result_tables(report: dict) -> list[Table]:
    cells = report["cells"]
    labels = [p["label"] for p in report["policies"]]
    perturbations = [p["name"] for p in report["perturbations"]]
    clips = list(dict.fromkeys(c["clip"] for c in cells))
    who = " / ".join(labels)
    tables = []
    for clip in clips:
        headers = ["perturbation"] + [METRIC_LABELS[k] for k in (*SUCCESS_KEYS, *METRIC_KEYS)] + ["episodes"]
        rows = []
        for p in perturbations:
            row = [perturbation_label(report, p)]
            for key in (*SUCCESS_KEYS, *METRIC_KEYS):
                getter = _e_o if key == "E_o_cm" else (lambda c, k=key: cell_value(c, k))
                row.append(_joined(cells, labels, clip, p, getter))
            row.append(_joined(cells, labels, clip, p, lambda c: c["episodes"]))
            rows.append(row)
        tables.append(Table(f"Tracking and success: {clip}" + (f" ({who})" if len(labels) > 1 else ""), headers, rows,
                            "means over episodes. " + definitions_note()))

        outcome_rows = []
        for p in perturbations:
            for label in labels:
                cell = _find(cells, label, clip, p)
                if cell is None:
                    continue
                text = "; ".join(f"{n}x {o}" for o, n in sorted(cell["outcomes"].items(), key=lambda kv: -kv[1]))
                if cell["errors"]:
                    text += f"; {len(cell['errors'])} episode(s) crashed: {cell['errors'][0]}"
                outcome_rows.append([p, label, text or "-"])
        tables.append(Table(f"Episode outcomes: {clip}", ["perturbation", "policy", "outcomes"], outcome_rows))

        hand_rows = []
        for p in perturbations:
            hand_rows.append([p] + [_joined(cells, labels, clip, p, _path("hand", k, "mean"), d) for k, d in (
                ("mean_command", 0), ("command_step", 1), ("closed_fraction", 2), ("tracking_error", 1),
                ("peak_force_g", 0))] + [_joined(cells, labels, clip, p, _bus_problems)])
        tables.append(Table(f"Hand commands: {clip}", ["perturbation", "mean ANGLE_SET", "step / tick",
                                                       "closed fraction", "tracking error (units)",
                                                       "peak FORCE_ACT (g)", "bus retries+errors"], hand_rows,
                            "ANGLE units 0..1000 (1000 = open); tracking error = |ANGLE_SET(t-1) - ANGLE_ACT(t)|"))

        timing_rows = []
        for p in perturbations:
            timing_rows.append([p] + [_joined(cells, labels, clip, p, getter, d) for getter, d in (
                (_path("timing", "policy_tick_wall_ms_p50", "mean"), 2),
                (_path("timing", "policy_tick_wall_ms_p99", "mean"), 2),
                (_path("runtime", "period_error_ms_p99", "mean"), 2),
                (_path("runtime", "clamped_ticks", "mean"), 1),
                (_path("timing", "torque_saturated_fraction", "mean", scale=100.0), 1),
                (_path("timing", "realtime_factor", "mean"), 1))])
        tables.append(Table(f"Loop timing: {clip}", ["perturbation", "tick wall p50 (ms)", "tick wall p99 (ms)",
                                                     "period error p99 (ms, sim)", "clamped ticks",
                                                     "torque-limited PD updates (%)", "real-time factor"], timing_rows,
                            "tick wall = wall time of one policy tick on this machine (observation, ONNX, "
                            "hand bytes, safety); period error: simulated clock vs the PD update grid; torque-limited: share of the PD "
                            "updates while the policy ran in which a motor hit its effort limit"))
    return tables


def setup_table(report: dict) -> Table:
    rows = [[p["label"], p["path"], p.get("policy_kind", "-"), (p.get("sha256") or "-")[:12],
             p.get("origin", "evaluated here")] for p in report["policies"]]
    return Table("Policies", ["label", "file", "kind", "sha256", "origin"], rows)


def perturbation_table(report: dict) -> Table:
    rows = [[p["name"], p["description"], p.get("physics", "")] for p in report["perturbations"]]
    return Table("Perturbations", ["name", "what changes", "physics"], rows)
