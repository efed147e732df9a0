"""`robot-hoi eval`: success, duration, E_h and E_o of a checkpoint (teacher, student or an untrained baseline),
per clip and pooled, under an evaluation protocol.

By default (`--protocol randomized`) each of the 32 episodes per clip starts from the default stand at the clip's
start with its position, heading and joints perturbed and the object's start pose perturbed (configs/eval/
randomized.yaml), every draw reproducible from --seed; `--protocol stand` is the one deterministic start (one
trajectory, however many episodes). Actions are the policy mean. Each episode is scored under two success
definitions on the same starts: ours (the task's terminations, object line 0.12 m; interaction success also needs
the object and body tracked throughout) and InterMimic's (supp. E: object and interaction lines 0.5 m, contact as
the simulator sees it). Rates come with 95 % Wilson intervals, means with 95 % t intervals. E_h: mean mapped-link
position error excluding the hands (cm); E_o: mean object surface-point error (cm), over the imitated duration.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from robot_hoi.data.cli_options import add_clip_options, clip_options
from robot_hoi.rl import evaluation


def register(subparsers) -> None:
    p = subparsers.add_parser("eval", help="evaluate a checkpoint under the randomized protocol: success with "
                                           "intervals, duration, E_h, E_o per clip", description=__doc__)
    p.add_argument("checkpoint", help="a model_*.pt from `robot-hoi train` or `robot-hoi train student`, a run or "
                                      "group folder (its model_best.pt, else the latest), or `untrained` for a baseline")
    p.add_argument("--data", nargs="*", default=None, help="clips (default: the ones the checkpoint trained on)")
    add_clip_options(p)
    add_protocol_options(p)
    p.add_argument("--embodiment", default="g1_inspire",
                   help="robot: a name under configs/embodiments/ or a YAML path")
    p.add_argument("--preset", default="fast", choices=["fast", "paper"], help="network for `untrained`")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="environment override on top of the checkpoint's task config, e.g. --set "
                        "env.self_collision=true (repeatable; applied after the protocol's settings)")
    p.add_argument("--json", action="store_true", help="print the evaluation record as JSON")
    p.add_argument("--out", metavar="FILE.json", help="write the evaluation record here (atomically), e.g. into "
                                                      "docs/results/data/ for `robot-hoi results`")
    p.add_argument("--label", help="what this evaluation stands for in the results tables (e.g. the recipe and "
                                   "budget); default: the checkpoint path")
    p.add_argument("--table", default="teachers", help="the results table this record belongs to")
    p.set_defaults(func=run)


def add_protocol_options(p: argparse.ArgumentParser) -> None:
    """The protocol flags `eval` and `compare` share."""
    p.add_argument("--protocol", default=evaluation.DEFAULT_PROTOCOL,
                   help="how episodes start: a name under configs/eval/ (randomized, stand) or a YAML path")
    p.add_argument("--episodes", type=int, default=evaluation.DEFAULT_EPISODES, help="episodes per clip")
    p.add_argument("--seed", type=int, default=evaluation.EVAL_SEED,
                   help=f"seeds every start draw (model selection in training uses {evaluation.VALIDATION_SEED}+)")
    p.add_argument("--mass-scale", type=float, nargs=2, metavar=("LO", "HI"), default=None,
                   help="draw the object's mass x LO..HI per episode (log-uniform; default: the clip's mass)")


def request_from_args(args: argparse.Namespace, checkpoint: str):
    from robot_hoi.rl.policy_eval import EvalRequest

    return EvalRequest(checkpoint=checkpoint, data=getattr(args, "data", None), protocol=args.protocol,
                       episodes=args.episodes, seed=args.seed,
                       mass_scale=tuple(args.mass_scale) if args.mass_scale else None,
                       overrides=list(getattr(args, "overrides", [])), embodiment=args.embodiment,
                       clip_options=clip_options(args) if hasattr(args, "objects") else None,
                       preset=getattr(args, "preset", "fast"))


def evaluate_checkpoint(request) -> dict:
    """The evaluation record of a teacher, a student or `untrained` (robot_hoi.rl.policy_eval.EvalRequest)."""
    from robot_hoi.rl.checkpoint import resolve_checkpoint
    from robot_hoi.rl.policy_eval import evaluate_teacher
    from robot_hoi.student.checkpoint import is_student_checkpoint
    from robot_hoi.student.eval_checkpoint import student_record

    if request.checkpoint != "untrained" and is_student_checkpoint(resolve_checkpoint(request.checkpoint)):
        return student_record(request)
    return evaluate_teacher(request)


def run(args: argparse.Namespace) -> int:
    record = evaluate_checkpoint(request_from_args(args, args.checkpoint))
    record["label"] = args.label or record["checkpoint"]
    record["table"] = args.table
    if args.out:
        from deploy.atomic import atomic_write_text

        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(Path(args.out), json.dumps(record, indent=1) + "\n")
    if args.json:
        print(json.dumps(record, indent=1))
    else:
        print_record(record)
        if args.out:
            print(f"wrote {args.out}")
    return 0


def _rate(r: dict, one_trajectory: bool = False) -> str:
    # a deterministic protocol repeats one trajectory: an interval over its copies would claim a sample it lacks
    return f"{r['rate']:.2f} (one trajectory)" if one_trajectory else f"{r['rate']:.2f} [{r['lo']:.2f}, {r['hi']:.2f}]"


def _mean(m: dict | None, fmt: str = ".1f") -> str:
    if m is None:  # a record written before the figure existed
        return "-"
    if m["lo"] is None:
        return format(m["mean"], fmt)
    return f"{m['mean']:{fmt}} [{m['lo']:{fmt}}, {m['hi']:{fmt}}]"


def print_record(record: dict) -> None:
    from rich.table import Table

    from robot_hoi.utils.console import table_console

    console = table_console()
    one = record["protocol"]["deterministic"]
    sections = [("", record["clips"], record["overall"])]
    if "distilled" in record:
        sections.append((" (its distilled reference)", record["distilled"]["clips"], record["distilled"]["overall"]))
    for suffix, clips, overall in sections:
        table = Table()
        for col in ("clip", "definition", "success (95 %)", "interaction", "duration s (95 %)", "of clip", "E_h cm",
                    "E_o cm", "E_o max", "E_o clip path"):
            table.add_column(col, justify="left" if col in ("clip", "definition") else "right")
        rows = [(name, clip, clip["clip_duration_s"]) for name, clip in clips.items()]
        if len(clips) > 1:
            rows.append(("all clips", overall, None))
        for name, clip, clip_s in rows:
            for definition in evaluation.DEFINITIONS:
                r = clip[definition]
                duration = _mean(r["duration_s"], ".2f") + (f" / {clip_s:.2f}" if clip_s else "")
                table.add_row(name if definition == "ours" else "", definition, _rate(r["success"], one),
                              _rate(r["interaction_success"], one) if definition == "ours" else "-", duration,
                              f"{100 * r['duration_share']['mean']:.0f} %", _mean(r["E_h_cm"]), _mean(r["E_o_cm"]),
                              f"{r['E_o_max_cm']['mean']:.1f}", _mean(r.get("E_o_source_cm")))
        # the heading on its own line: a table title wraps at the table's width, splitting long checkpoint paths
        console.print(f"robot-hoi eval{suffix}: {record['checkpoint']}", markup=False, highlight=False)
        console.print(table)
        for name, clip in clips.items():
            for definition in evaluation.DEFINITIONS:
                ended = ", ".join(f"{k} {v:.2f}" for k, v in clip[definition]["ended_by"].items())
                print(f"{name} ({definition}): episodes ended by {ended}")
    print(protocol_line(record["protocol"]))


def protocol_line(protocol: dict) -> str:
    line = (f"protocol {protocol['name']}: {protocol['episodes_per_clip']} episodes per clip, seed {protocol['seed']} "
            f"(model selection in training used seeds from {protocol['validation_seed']})")
    if protocol["deterministic"]:
        line += "; every start is the same: the episodes are one trajectory, a sample of one"
    return line
