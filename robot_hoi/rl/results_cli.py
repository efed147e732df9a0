"""`robot-hoi results`: regenerate docs/results/README.md from the evaluation records in docs/results/data/
(`robot-hoi eval --out` records and sim2sim reports). `--check` fails when the committed tables are not what the
records give."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from robot_hoi.paths import REPO_ROOT

RESULTS_DIR = REPO_ROOT / "docs" / "results"


def register(subparsers) -> None:
    p = subparsers.add_parser("results", help="regenerate docs/results/README.md from its JSON records",
                              description=__doc__)
    p.add_argument("--data", default=str(RESULTS_DIR / "data"), help="folder of JSON records")
    p.add_argument("--out", default=str(RESULTS_DIR / "README.md"), help="the generated tables")
    p.add_argument("--check", action="store_true", help="only check that --out is up to date (exit 1 if not)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from deploy.atomic import atomic_write_text
    from robot_hoi.rl.results import load_records, render

    text = render(load_records(Path(args.data)))
    out = Path(args.out)
    if args.check:
        if not out.is_file() or out.read_text() != text:
            print(f"{out} is not what {args.data} gives: run `robot-hoi results`", file=sys.stderr)
            return 1
        print(f"{out} is up to date")
        return 0
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out, text)
    print(f"wrote {out} from {len(list(Path(args.data).glob('*.json')))} record(s)")
    return 0
