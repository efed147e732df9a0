"""`robot-hoi results`: regenerate docs/results/README.md from the evaluation records in docs/results/data/
(`robot-hoi eval --out` records and sim2sim reports), and the results blocks of the top-level README
(`<!-- results: STEM -->` ... `<!-- /results -->`). `--check` fails when either is not what the records give."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from robot_hoi.paths import REPO_ROOT

ROOT = REPO_ROOT if REPO_ROOT is not None else Path()  # under an installed wheel: the checkout one works in
RESULTS_DIR = ROOT / "docs" / "results"


def register(subparsers) -> None:
    p = subparsers.add_parser("results", help="regenerate docs/results/README.md from its JSON records",
                              description=__doc__)
    p.add_argument("--data", default=str(RESULTS_DIR / "data"), help="folder of JSON records")
    p.add_argument("--out", default=str(RESULTS_DIR / "README.md"), help="the generated tables")
    p.add_argument("--readme", default=str(ROOT / "README.md"),
                   help="a guide whose results blocks are filled from the records")
    p.add_argument("--check", action="store_true", help="only check that --out is up to date (exit 1 if not)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from deploy.atomic import atomic_write_text
    from robot_hoi.errors import UserError
    from robot_hoi.rl.results import fill_blocks, load_records, render

    records = load_records(Path(args.data))
    out, readme = Path(args.out), Path(args.readme)
    if not readme.is_file():
        raise UserError(f"{readme}: no such file (--readme)")
    wanted = {out: render(records), readme: fill_blocks(readme.read_text(), records, str(readme))}
    stale = [path for path, text in wanted.items() if not path.is_file() or path.read_text() != text]
    if args.check:
        for path in stale:
            print(f"{path} is not what {args.data} gives: run `robot-hoi results`", file=sys.stderr)
        if not stale:
            print(f"{out} and {readme} are up to date")
        return 1 if stale else 0
    out.parent.mkdir(parents=True, exist_ok=True)
    for path in stale:
        atomic_write_text(path, wanted[path])
    print(f"{out} and the blocks of {readme} from {len(records)} record(s)"
          + (f"; rewrote {', '.join(map(str, stale))}" if stale else "; nothing changed"))
    return 0
