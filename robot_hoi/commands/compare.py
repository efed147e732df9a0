"""`robot-hoi compare`: is recipe A better than recipe B? Each run (one seed of a recipe) is evaluated at its chosen
checkpoint (model_best.pt, else the latest) under the same protocol as `robot-hoi eval`; per metric it prints the
mean and range over seeds, the 95 % interval of every episode pooled, and whether the recipes separate: at least
two seeds each, pooled intervals apart, and every seed of one above every seed of the other.

    robot-hoi compare runs/tight/seed_1 runs/tight/seed_2 --vs runs/base/seed_1 runs/base/seed_2
    robot-hoi compare runs/tight --vs runs/base     # folders of `robot-hoi train --seeds`: their seed_* runs
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from robot_hoi.commands.eval import add_protocol_options


def register(subparsers) -> None:
    p = subparsers.add_parser("compare", help="compare two recipes over their seeds under the evaluation protocol",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", nargs="+", help="recipe A: run folders or checkpoints, one per seed (a folder of "
                                           "seed_* runs stands for all of them)")
    p.add_argument("--vs", nargs="+", required=True, metavar="RUN", help="recipe B, as recipe A")
    p.add_argument("--names", nargs=2, default=("A", "B"), metavar=("A", "B"), help="the two recipes' names")
    add_protocol_options(p)
    p.add_argument("--embodiment", default="g1_inspire", help="robot: a name under configs/embodiments/ or a YAML path")
    p.add_argument("--out", metavar="FILE.json", help="write the comparison and every evaluation record here")
    p.set_defaults(func=run)


def expand_runs(paths: list[str]) -> list[str]:
    """A folder holding seed_* runs (`robot-hoi train --seeds`) stands for each of them."""
    runs: list[str] = []
    for path in paths:
        seeds = sorted(Path(path).glob("seed_*")) if Path(path).is_dir() else []
        runs += [str(s) for s in seeds if s.is_dir()] or [path]
    return runs


def run(args: argparse.Namespace) -> int:
    from robot_hoi.commands.eval import evaluate_checkpoint, protocol_line, request_from_args
    from robot_hoi.rl.compare import compare_records

    sides = {}
    for name, paths in zip(args.names, (args.runs, args.vs), strict=True):
        records = []
        for run_path in expand_runs(paths):
            record = evaluate_checkpoint(request_from_args(args, run_path))
            overall = record["overall"]["ours"]
            print(f"{name}: {record['checkpoint']}: success {overall['success']['rate']:.2f}, interaction "
                  f"{overall['interaction_success']['rate']:.2f}, {100 * overall['duration_share']['mean']:.0f} % "
                  f"of the clip")
            records.append(record)
        sides[name] = records
    a, b = (sides[n] for n in args.names)
    comparison = compare_records(a, b, tuple(args.names))
    print(protocol_line(a[0]["protocol"]))
    for metric, result in comparison.items():
        print(f"{metric}:")
        for label in args.names:
            s = result[label]
            print(f"  {label}: mean over {len(s['seeds'])} seeds {s['mean']:.3f} (range {s['min']:.3f}-{s['max']:.3f});"
                  f" {s['episodes']} episodes pooled {s['pooled']:.3f} [{s['lo']:.3f}, {s['hi']:.3f}]")
        print(f"  {result['statement']}")
    if args.out:
        from deploy.atomic import atomic_write_text

        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(Path(args.out), json.dumps({"names": list(args.names), "comparison": comparison,
                                                      "records": sides}, indent=1) + "\n")
    return 0
