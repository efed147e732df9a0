"""Episode results -> one aggregate "cell" per (policy, clip, perturbation), as metrics.json stores them."""

from __future__ import annotations

from collections import Counter

from sim2sim.metrics import aggregate

METRIC_KEYS = ("duration_s", "E_h_cm", "E_o_cm", "mpjpe_g_mm", "mpjpe_mm", "e_acc_mm", "e_vel_mm")
HAND_KEYS = ("mean_command", "command_step", "closed_fraction", "open_fraction", "tracking_error",
             "peak_force_g", "mean_force_g")
METRIC_LABELS = {
    "success_rate": "success",
    "interaction_success_rate": "interaction success",
    "duration_s": "duration (s)",
    "E_h_cm": "E_h (cm)",
    "E_o_cm": "E_o (cm)",
    "mpjpe_g_mm": "g-MPJPE (mm)",
    "mpjpe_mm": "MPJPE (mm)",
    "e_acc_mm": "E_acc (mm/frame^2)",
    "e_vel_mm": "E_vel (mm/frame)",
}


# What each metric means, printed where it appears (report tables, summary.md).
METRIC_DEFINITIONS = {
    "success_rate": "share of episodes that reached the clip's end without an InterMimic early termination or a "
                    "runtime fault",
    "interaction_success_rate": "share of episodes that succeeded and also kept the object (mean surface-point "
                                "error) and the body (mean link error) within the task config's "
                                "success_max_object_error / success_max_link_error at every tracked frame: a "
                                "policy that never lifts the object can succeed, not interaction-succeed",
    "duration_s": "seconds of the clip tracked before the episode ended",
    "E_h_cm": "mean distance between the robot's body links and the reference's, hands excluded",
    "E_o_cm": "mean distance between the object's surface points and the reference object's; small also when the "
              "object was never touched and simply stayed where the reference starts, hence the touch note",
    "mpjpe_g_mm": "g-MPJPE: mean link position error in the world frame",
    "mpjpe_mm": "MPJPE: mean link position error relative to the pelvis",
    "e_acc_mm": "E_acc: mean difference of link accelerations (per frame^2)",
    "e_vel_mm": "E_vel: mean difference of link velocities (per frame)",
}


SUCCESS_KEYS = ("success_rate", "interaction_success_rate")


def definitions_note(keys=(*SUCCESS_KEYS, *METRIC_KEYS)) -> str:
    return "; ".join(f"{METRIC_LABELS[k]}: {METRIC_DEFINITIONS[k]}" for k in keys)


def episode_record(result: dict) -> dict:
    """One episode as stored in metrics.json (no traces)."""
    return {k: v for k, v in result.items() if k != "trace"}


def build_cells(results: list[dict]) -> list[dict]:
    groups: dict[tuple[str, str, str], list[dict]] = {}
    for r in results:
        groups.setdefault((r["policy"], r["clip"], r["perturbation"]), []).append(r)
    return [_cell(key, episodes) for key, episodes in groups.items()]


def _cell(key: tuple[str, str, str], episodes: list[dict]) -> dict:
    policy, clip, perturbation = key
    ok = [e for e in episodes if "error" not in e]
    cell = {
        "policy": policy,
        "clip": clip,
        "perturbation": perturbation,
        "episodes": len(episodes),
        "errors": [e["error"] for e in episodes if "error" in e],
        "success_rate": (sum(bool(e["success"]) for e in ok) / len(ok)) if ok else None,
        "interaction_success_rate": _interaction_rate(ok),
        "outcomes": dict(Counter(e["outcome"] for e in ok)),
        "touched_episodes": sum(bool(e.get("object_touched")) for e in ok),
        "fell_episodes": sum(bool(e.get("fell")) for e in ok),
        "pushes_applied": sum(e.get("pushes_in_episode", len(e.get("pushes") or [])) for e in ok),
    }
    for k in METRIC_KEYS:
        cell[k] = aggregate(e[k] for e in ok)
    cell["hand"] = {k: aggregate(e["hand"][k] for e in ok) for k in HAND_KEYS}
    bus = Counter()
    for e in ok:
        for side in e["hand"]["bus"].values():
            bus.update({k: side.get(k, 0) for k in ("cycles", "link_errors", "fault_errors", "reconnects",
                                                    "late_cycles", "bus_retries")})
    cell["hand_bus"] = dict(bus)
    cell["runtime"] = {
        "episodes_with_faults": sum(bool(e["runtime"]["faults"]) for e in ok),
        "faults": sorted({f for e in ok for f in e["runtime"]["faults"]}),
        "clamped_ticks": aggregate(e["runtime"]["clamped_ticks"] for e in ok),
        "rate_limited_ticks": aggregate(e["runtime"]["rate_limited_ticks"] for e in ok),
        "overruns": sum(e["runtime"]["overruns"] for e in ok),
        "period_error_ms_p99": aggregate(e["runtime"]["period_error_ms"]["p99"] for e in ok),
    }
    cell["timing"] = {
        "policy_tick_wall_ms_p50": aggregate(e["timing"]["policy_tick_wall_ms"]["p50"] for e in ok),
        "policy_tick_wall_ms_p99": aggregate(e["timing"]["policy_tick_wall_ms"]["p99"] for e in ok),
        "realtime_factor": aggregate(e["timing"]["realtime_factor"] for e in ok),
        "torque_saturated_fraction": aggregate(e["timing"]["torque_saturated_fraction"] for e in ok),
    }
    return cell


def _interaction_rate(episodes: list[dict]) -> float | None:
    judged = [e["interaction_success"] for e in episodes if e.get("interaction_success") is not None]
    return sum(judged) / len(judged) if judged else None


def cell_value(cell: dict, key: str) -> float | None:
    """A rate (the success rates) as it is, a metric's aggregate by its mean."""
    value = cell.get(key)
    return value.get("mean") if isinstance(value, dict) else value
