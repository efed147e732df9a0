"""`robot-hoi sim2sim`: validate a deployable ONNX policy in a second simulation, driven by the robot runtime.

Only argparse here; the simulation is imported inside the handler so `robot-hoi --help` stays fast.
"""

from __future__ import annotations

import argparse
import sys

from robot_hoi.data.cli_options import add_clip_options, clip_options

EPILOG = """examples:
  robot-hoi export onnx --untrained -o policies/untrained.onnx
  robot-hoi sim2sim --policy policies/untrained.onnx -o reports/untrained
  robot-hoi sim2sim --policy policies/student.onnx --suite robust --episodes 5 -o reports/student-robust
  robot-hoi sim2sim --policy policies/student.onnx --suite hardware -o reports/student-hardware
  robot-hoi sim2sim --policy policies/student.onnx --compare policies/student_v2.onnx -o reports/v1-vs-v2
  robot-hoi sim2sim --policy policies/student.onnx --compare reports/student-robust -o reports/again
  robot-hoi sim2sim --policy P.onnx --clips ../shared/reference/motions/clips/sub3_largebox_003.pt

The report folder holds metrics.json, summary.md, report.html (plots embedded) and videos/*.mp4.
Videos render offscreen with MUJOCO_GL=egl or osmesa; without a working backend the report keeps its plots."""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "sim2sim",
        help="validate an ONNX policy in MuJoCo through the deploy runtime (perturbation suites, reports)",
        description=__doc__.splitlines()[0],
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--policy", required=True, help="deployable ONNX policy (robot-hoi export onnx)")
    p.add_argument("--motion", default=None,
                   help="reference .motion.npz to track (default: the policy's sidecar); the object is the one of "
                        "the clip the policy names; use --clips for other clips")
    p.add_argument("--clips", nargs="+", default=None, metavar="CLIP",
                   help="evaluate on these clips (files, folders or embedded:lift_carry), retargeted as in training")
    add_clip_options(p)
    p.add_argument("--suite", default="default", choices=("nominal", "default", "robust", "hardware"),
                   help="nominal only; default = nominal + a few; robust = the full perturbation grid; hardware = "
                        "what the robot meets, READY only when every condition reaches --ready-success over "
                        "16+ episodes")
    p.add_argument("--perturbations", nargs="+", default=None, metavar="NAME",
                   help="run only these perturbations (any suite's names, e.g. object_mass_x10 push_0.3)")
    p.add_argument("--episodes", type=int, default=None,
                   help="episodes per clip and perturbation (default 3; 16 for --suite hardware)")
    p.add_argument("-o", "--output", default=None, help="report folder (default reports/sim2sim-<time>)")
    p.add_argument("--compare", default=None, metavar="POLICY_OR_RUN",
                   help="a second .onnx policy to evaluate alongside, or a previous report folder / metrics.json")
    p.add_argument("--workers", type=int, default=None, help="parallel processes (default: one per core)")
    p.add_argument("--seconds", type=float, default=None,
                   help="evaluate only the first SECONDS of each clip (quick checks)")
    p.add_argument("--hand-bus", choices=("serial", "modbus", "can"), default="serial",
                   help="the Inspire protocol the runtime speaks to the simulated hands (default serial)")
    p.add_argument("--hand-link", choices=("direct", "pty"), default=None,
                   help="direct: bytes handed to the device in-process (default; serial/modbus); pty: the "
                        "device's own thread on a pseudo-terminal / virtual CAN, as deploy --dry-run")
    p.add_argument("--videos", type=int, default=2,
                   help="episodes to render as MP4: the first of each policy, then the worst (0 = none)")
    p.add_argument("--embodiment", default="g1_inspire", help="embodiment name or YAML path")
    p.add_argument("--seed", type=int, default=0, help="seed of noise, pushes and spawn offsets")
    p.add_argument("--no-self-collision", action="store_true",
                   help="turn robot self-collision off (on by default: the real robot has no collision filter)")
    p.add_argument("--tracker-rate", type=float, default=120.0, help="simulated mocap rate in Hz (default 120)")
    p.add_argument("--min-success", type=float, default=None, metavar="RATE",
                   help="exit 1 when the first policy's nominal success rate is below RATE (a CI gate)")
    p.add_argument("--ready-success", type=float, default=0.8, metavar="RATE",
                   help="verdict: nominal success rate a ready policy reaches on every clip")
    p.add_argument("--ready-e-h", type=float, default=10.0, metavar="CM",
                   help="verdict: largest nominal E_h (cm, body links vs reference) of a ready policy")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=handler)


def handler(args: argparse.Namespace) -> int:
    from sim2sim.evaluate import Sim2SimOptions, evaluate
    from sim2sim.perturbations import EVERY_CONDITION_SUITES
    from sim2sim.report import fmt_rtf
    from sim2sim.verdict import ReadyThresholds

    episodes = args.episodes
    if episodes is None:  # a verdict on every condition needs its episodes (ReadyThresholds.min_episodes)
        episodes = ReadyThresholds.min_episodes if args.suite in EVERY_CONDITION_SUITES and not args.perturbations \
            else 3
    options = Sim2SimOptions(
        policy=args.policy, motion=args.motion, clips=args.clips, suite=args.suite,
        perturbations=args.perturbations, episodes=episodes, output=args.output, compare=args.compare,
        workers=args.workers, seconds=args.seconds, hand_transport=args.hand_bus, hand_link=args.hand_link,
        embodiment=args.embodiment, videos=args.videos, seed=args.seed, self_collision=not args.no_self_collision,
        tracker_rate_hz=args.tracker_rate, quiet=args.quiet, argv=sys.argv[1:], clip_options=clip_options(args),
        ready=ReadyThresholds(min_success=args.ready_success, max_e_h_cm=args.ready_e_h),
    )
    report, paths = evaluate(options)
    main = report["policies"][0]["label"]
    from sim2sim.summary import SUCCESS_KEYS
    from sim2sim.verdict import verdict_lines

    for line in verdict_lines(report["verdict"]) if report.get("verdict") else []:
        print(line)
    print(f"sim2sim report: {paths['html']}")
    print(f"  metrics {paths['metrics']}, summary {paths['summary']}, {len(report['videos'])} video(s)")
    for cell in report["cells"]:
        if cell["policy"] != main:
            continue
        success, interaction = (("-" if cell.get(k) is None else f"{cell[k]:.2f}") for k in SUCCESS_KEYS)
        e_h = cell["E_h_cm"]["mean"]
        print(f"  {cell['clip']:<28} {cell['perturbation']:<24} success {success} (interaction {interaction})  "
              f"E_h {'-' if e_h is None else f'{e_h:.1f} cm'}")
    t = report["timing"]
    print(f"  {t['simulated_s']:.1f} simulated s in {t['wall_s']:.1f} s on {t['workers']} process(es): an episode ran "
          f"at {fmt_rtf(t['realtime_factor_per_episode'])} x real time, "
          f"{fmt_rtf(t['realtime_factor_per_cpu_second'])} x per CPU second")
    errors = [e for c in report["cells"] for e in c["errors"]]
    if errors:
        print(f"  {len(errors)} episode(s) crashed; first: {errors[0]}", file=sys.stderr)
        return 1
    if args.min_success is not None:
        nominal = [c for c in report["cells"] if c["policy"] == main and c["perturbation"] == "nominal"]
        rates = [c["success_rate"] for c in nominal if c["success_rate"] is not None]
        if not rates:
            print("  --min-success: no nominal episodes were run", file=sys.stderr)
            return 1
        if min(rates) < args.min_success:
            print(f"  nominal success {min(rates):.2f} < --min-success {args.min_success}", file=sys.stderr)
            return 1
    return 0
