"""A teacher run's learning curve: the rows its in-training evaluation appends to eval_curve.jsonl (one per
`runner.eval_interval` iterations: step, samples, train_time_s, eval_s and the evaluation's metrics), read back and
summarised. Light (no torch): the runner writes the file, `robot-hoi curve` reads it."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from robot_hoi.errors import UserError

EVAL_CURVE_FILE = "eval_curve.jsonl"


def eval_rank(metrics: dict) -> tuple[float, float, float]:
    """Which evaluation is better (the one model_best.pt keeps): success first, then interaction success (the object
    also tracked), then how long the clip was tracked. Measured on embedded:lift_place (intermimic_paper, seed 1):
    success reached 1.00 two evaluations before interaction success did (0.44 -> 0.88 -> 1.00)."""
    return (float(metrics["success_rate"]), float(metrics.get("interaction_success_rate", 0.0)),
            float(metrics["duration_s"]))


@dataclass
class Curve:
    label: str
    path: Path
    rows: list[dict]


def find_curves(paths: list[str]) -> list[Curve]:
    """The eval curves under each path (a curve file, or a folder searched recursively), labelled by their folder
    relative to the path given (or the path itself when it is the group folder)."""
    curves = []
    for given in paths:
        root = Path(given)
        if root.is_file():
            files = [root]
        elif root.is_dir():
            files = sorted(root.rglob(EVAL_CURVE_FILE))
        else:
            raise UserError(f"{root}: no such file or folder")
        if not files:
            raise UserError(f"{root}: no {EVAL_CURVE_FILE} under it (runs write one when runner.eval_interval > 0)")
        for file in files:
            label = str(file.parent) if root.is_file() else str(root / file.parent.relative_to(root))
            curves.append(Curve(label.removesuffix("/."), file, read_curve(file)))
    return curves


def read_curve(path: Path) -> list[dict]:
    """Rows of an eval_curve.jsonl; a malformed line is an error naming the file and line."""
    rows = []
    needed = ("step", "samples", "train_time_s", "eval_s", "success_rate", "duration_s")
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError as err:
            raise UserError(f"{path}: line {number} is not JSON ({err.msg})") from None
        missing = [k for k in needed if k not in row] if isinstance(row, dict) else list(needed)
        if missing:
            raise UserError(f"{path}: line {number} lacks {', '.join(missing)}")
        rows.append(row)
    return rows


def with_wall_time(rows: list[dict]) -> list[dict]:
    """Rows with `wall_time_s`: training time plus the evaluations so far (what the run took on the clock)."""
    evals, out = 0.0, []
    for row in rows:
        evals += float(row["eval_s"])
        out.append({**row, "wall_time_s": float(row["train_time_s"]) + evals})
    return out


def summarize(rows: list[dict], tail: int = 3) -> dict:
    """First evaluation at success 1.0, the best (the runner's rank: eval_rank), the last, and the mean
    duration and success of the last `tail` evaluations, over the rows validated like the last one (a run resumed
    with domain randomisation switched on validates under it from then on: its rows are not compared with the
    nominal ones before, as the runner does for model_best.pt)."""
    rows = with_wall_time(rows)
    if not rows:
        return {"evaluations": 0}
    validation = rows[-1].get("validation")
    other = sum(r.get("validation") != validation for r in rows)
    rows = [r for r in rows if r.get("validation") == validation]
    first = next((r for r in rows if r["success_rate"] >= 1.0), None)
    best = max(rows, key=eval_rank)  # the first of equals, as the runner keeps
    late = rows[-max(tail, 1):]
    pick = ("step", "samples", "train_time_s", "wall_time_s", "success_rate", "interaction_success_rate",
            "duration_s", "E_h_cm", "E_o_max_cm")
    return {
        "evaluations": len(rows),
        "first_full_success": {k: first.get(k) for k in pick} if first else None,
        "best": {k: best.get(k) for k in pick},
        "last": {k: rows[-1].get(k) for k in pick},
        "late_mean_duration_s": sum(r["duration_s"] for r in late) / len(late),
        "late_mean_success": sum(r["success_rate"] for r in late) / len(late),
        "late_evaluations": len(late),
        "validation": validation or "protocol starts",
        "evaluations_validated_otherwise": other,
    }
