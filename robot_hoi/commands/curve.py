"""`robot-hoi curve`: learning curves of teacher runs from their in-training evaluation (eval_curve.jsonl).

Every `runner.eval_interval` iterations a teacher job scores its policy on stand starts (with the training's spawn
noise) and appends a row to `<group>/eval_curve.jsonl`. This command prints those rows against training time (wall
time without the evaluations), wall time (with them) and samples, one table per curve, then one summary line per
curve: the first evaluation at full success, the best (the row model_best.pt holds), the last, and the mean tracked
duration of the last `--tail` evaluations (single evaluations flip). `--plot` draws success and duration against
training minutes (or samples) for all curves on one figure, for side-by-side runs (seeds, reward sets).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from robot_hoi.rl.eval_curve import Curve, find_curves, summarize, with_wall_time


def register(subparsers) -> None:
    p = subparsers.add_parser("curve", help="learning curves of teacher runs (their in-training evaluations)",
                              description=__doc__)
    p.add_argument("runs", nargs="+", help="run or group folders (searched for eval_curve.jsonl) or curve files")
    p.add_argument("--tail", type=int, default=3, help="evaluations averaged for the summary's late duration")
    p.add_argument("--plot", help="write a figure (.png/.svg/.pdf) of success and duration for all curves")
    p.add_argument("--x", choices=("time", "samples"), default="time",
                   help="plot against training minutes or million samples")
    p.add_argument("--json", action="store_true", help="print the curves and summaries as JSON")
    p.set_defaults(func=run)


def format_table(curve: Curve) -> str:
    lines = [f"{curve.label}  ({curve.path})",
             "    it  train min  wall min  samples  success  interact  duration s  E_h cm  E_o max cm"]
    for r in with_wall_time(curve.rows):
        lines.append(f"{r['step']:6d} {r['train_time_s'] / 60:10.1f} {r['wall_time_s'] / 60:9.1f} "
                     f"{r['samples'] / 1e6:7.2f}M {r['success_rate']:8.2f} "
                     f"{r.get('interaction_success_rate', float('nan')):9.2f} {r['duration_s']:11.2f} "
                     f"{r.get('E_h_cm', float('nan')):7.1f} {r.get('E_o_max_cm', float('nan')):11.1f}"
                     f"{'  *' if r.get('best') else ''}"
                     f"{'  (under ' + r['validation'] + ')' if r.get('validation') else ''}")
    return "\n".join(lines)


def format_summary(label: str, s: dict) -> str:
    if not s["evaluations"]:
        return f"{label}: no evaluations"

    def at(r):
        return f"{r['train_time_s'] / 60:.1f} min / {r['samples'] / 1e6:.2f} M"

    first = s["first_full_success"]
    best, last = s["best"], s["last"]
    return (f"{label}: first success 1.00 {'at ' + at(first) if first else 'never'}; best {best['success_rate']:.2f} "
            f"/ {best['duration_s']:.2f} s at {at(best)}; last {last['success_rate']:.2f} / {last['duration_s']:.2f} s "
            f"at {at(last)}; last {s['late_evaluations']}: success {s['late_mean_success']:.2f}, duration "
            f"{s['late_mean_duration_s']:.2f} s"
            + (f" (rows validated under {s['validation']}; {s['evaluations_validated_otherwise']} validated otherwise "
               "left out)" if s["evaluations_validated_otherwise"] else ""))


def plot(curves: list[Curve], path: Path, x: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from deploy.atomic import atomic_path

    fig, (ax_s, ax_d) = plt.subplots(2, 1, sharex=True, figsize=(8, 6))
    for curve in curves:
        rows = curve.rows
        xs = [r["train_time_s"] / 60 if x == "time" else r["samples"] / 1e6 for r in rows]
        ax_s.plot(xs, [r["success_rate"] for r in rows], marker=".", label=curve.label)
        ax_d.plot(xs, [r["duration_s"] for r in rows], marker=".", label=curve.label)
    ax_s.set_ylabel("success (eval)")
    ax_d.set_ylabel("tracked duration (s)")
    ax_d.set_xlabel("training minutes" if x == "time" else "million samples")
    ax_s.legend(fontsize="small")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=path.suffix.lstrip(".").lower())  # run() checked the suffix
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    from robot_hoi.errors import UserError

    if args.tail < 1:
        raise UserError(f"--tail must be >= 1, got {args.tail}")
    if args.plot and Path(args.plot).suffix.lower() not in (".png", ".svg", ".pdf"):
        raise UserError(f"{args.plot}: the figure must end in .png, .svg or .pdf")
    curves = find_curves(args.runs)
    summaries = {c.label: summarize(c.rows, args.tail) for c in curves}
    if args.plot:
        plot(curves, Path(args.plot), args.x)
    if args.json:
        print(json.dumps({c.label: {"file": str(c.path), "rows": with_wall_time(c.rows), "summary": summaries[c.label]}
                          for c in curves}, indent=1))
        return 0
    for curve in curves:
        print(format_table(curve))
        print()
    for curve in curves:
        print(format_summary(curve.label, summaries[curve.label]))
    if args.plot:
        print(f"wrote {args.plot}")
    return 0
