"""The report's first line: can this policy run on the robot? Ready when the first policy, on every clip, meets
each threshold below in the nominal (unperturbed) condition and never faulted the runtime; the lines say which
threshold decided and how to change it. A suite that judges every condition (perturbations.EVERY_CONDITION_SUITES:
hardware) also needs the success threshold in each perturbed condition, over at least min_episodes episodes
each, with interaction success reported beside it.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from sim2sim.perturbations import EVERY_CONDITION_SUITES
from sim2sim.summary import cell_value


@dataclass(frozen=True)
class ReadyThresholds:
    min_success: float = 0.8  # --ready-success
    max_e_h_cm: float = 10.0  # --ready-e-h
    max_tick_ms: float | None = None  # policy tick wall p99; None: the control period (the loop must keep time)
    # episodes per condition behind a verdict on every condition: 16 tell 0.8 from 0.5 (Wilson 95 % interval of
    # 13/16 is 0.57-0.93)
    min_episodes: int = 16


FLAGS = {"min_success": "--ready-success RATE", "max_e_h_cm": "--ready-e-h CM", "min_episodes": "--episodes N"}


def verdict(report: dict, thresholds: ReadyThresholds = ReadyThresholds()) -> dict:
    """{"ready": bool, "checks": [(ok, line)], "thresholds": {...}} for the first policy's nominal cells (and, in a
    suite judged on every condition, its other cells)."""
    policy = report["policies"][0]["label"]
    period_ms = 1e3 * report["policies"][0].get("control_dt", 0.02)
    max_tick = thresholds.max_tick_ms or period_ms
    nominal = report["perturbations"][0]["name"]
    cells = [c for c in report["cells"] if c["policy"] == policy and c["perturbation"] == nominal]
    checks = []
    for cell in cells:
        clip = cell["clip"]
        success, e_h = cell_value(cell, "success_rate"), cell_value(cell, "E_h_cm")
        tick = (cell.get("timing", {}).get("policy_tick_wall_ms_p99") or {}).get("mean")
        checks.append((success is not None and success >= thresholds.min_success,
                       f"{clip}: success {_f(success)} (needs >= {thresholds.min_success:g}, "
                       f"{FLAGS['min_success']})"))
        interaction = cell_value(cell, "interaction_success_rate")
        if interaction is not None:  # reaching the end without carrying the object is not ready
            checks.append((interaction >= thresholds.min_success,
                           f"{clip}: interaction success {_f(interaction)} (needs >= {thresholds.min_success:g}, "
                           f"{FLAGS['min_success']})"))
        checks.append((e_h is not None and e_h <= thresholds.max_e_h_cm,
                       f"{clip}: E_h {_f(e_h, 1)} cm (needs <= {thresholds.max_e_h_cm:g} cm, {FLAGS['max_e_h_cm']})"))
        faults = cell.get("runtime", {}).get("episodes_with_faults", 0) + len(cell.get("errors", []))
        checks.append((faults == 0, f"{clip}: {faults} episode(s) with runtime faults or crashes (needs 0)"))
        if tick is not None:
            checks.append((tick <= max_tick, f"{clip}: policy tick p99 {tick:.2f} ms on this machine (needs <= "
                                             f"{max_tick:.1f} ms, the control period)"))
        if cell.get("fell_episodes"):
            checks.append((False, f"{clip}: the robot fell in {cell['fell_episodes']} of {cell['episodes']} "
                                  "episode(s)"))
    every = report.get("suite") in EVERY_CONDITION_SUITES
    if every:
        checks += _condition_checks(report, policy, thresholds)
    ready = bool(checks) and all(ok for ok, _ in checks)
    condition = f"every condition of the {report['suite']} suite" if every else f"the {nominal} condition"
    return {"ready": ready, "policy": policy, "condition": condition, "checks": checks,
            "thresholds": asdict(thresholds) if every else
            {k: v for k, v in asdict(thresholds).items() if k != "min_episodes"}}


def _condition_checks(report: dict, policy: str, thresholds: ReadyThresholds) -> list[tuple[bool, str]]:
    """Per condition and clip: success at the threshold over at least min_episodes episodes (interaction success
    beside it); a condition the report lacks fails."""
    checks = []
    cells = {(c["perturbation"], c["clip"]): c for c in report["cells"] if c["policy"] == policy}
    clips = sorted({clip for _, clip in cells})
    for perturbation in (p["name"] for p in report["perturbations"]):
        for clip in clips:
            cell = cells.get((perturbation, clip))
            if cell is None:
                checks.append((False, f"{clip} {perturbation}: not evaluated"))
                continue
            success, n = cell_value(cell, "success_rate"), cell["episodes"]
            interaction = cell_value(cell, "interaction_success_rate")
            ok = success is not None and success >= thresholds.min_success and n >= thresholds.min_episodes
            checks.append((ok, f"{clip} {perturbation}: success {_f(success)} over {n} episodes (interaction "
                               f"{_f(interaction)}) (needs >= {thresholds.min_success:g} over >= "
                               f"{thresholds.min_episodes} episodes, {FLAGS['min_success']}, {FLAGS['min_episodes']})"))
    return checks


def verdict_lines(v: dict) -> list[str]:
    """The headline, then the checks that failed (all checks when ready)."""
    head = (f"READY: {v['policy']} meets every threshold in {v['condition']}" if v["ready"] else
            f"NOT READY: {v['policy']} misses {sum(not ok for ok, _ in v['checks'])} threshold(s) in "
            f"{v['condition']}")
    shown = [line for ok, line in v["checks"] if v["ready"] or not ok]
    flags = [flag for key, flag in FLAGS.items() if key in v["thresholds"]]
    return [head, *shown, "thresholds: " + ", ".join(f"{k} {val}" for k, val in v["thresholds"].items()
                                                     if val is not None) + "; change them with "
            + " / ".join(flags) + " (robot-hoi sim2sim --help)"]


def _f(value, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"
