"""`robot-hoi model ...`: joint/actuator table, MJCF and URDF export, viewer and offscreen render."""

from __future__ import annotations

import argparse
import json
import sys

DEFAULT_EMBODIMENT = "g1_inspire"


def register(subparsers) -> None:
    p = subparsers.add_parser("model", help="the robot model: joint table, MJCF/URDF export, viewer, render")
    p.set_defaults(func=lambda args: _usage(p))
    actions = p.add_subparsers(dest="model_action", metavar="ACTION")

    def common(sub: argparse.ArgumentParser) -> None:
        sub.add_argument("--embodiment", default=DEFAULT_EMBODIMENT,
                         help="name in configs/embodiments/ or a YAML path (default: %(default)s)")
        sub.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                         help="override a config value, e.g. --set decimation=4 (repeatable)")

    def self_collision(sub: argparse.ArgumentParser) -> None:
        sub.add_argument("--self-collision", choices=("on", "off"), default=None,
                         help="robot-robot contacts (default: the embodiment's self_collision)")

    def meshes(sub: argparse.ArgumentParser) -> None:
        sub.add_argument("--meshes", action=argparse.BooleanOptionalAction, default=True,
                         help="show Unitree's STL meshes when the reference folder is present (default: on)")

    show = actions.add_parser("show", help="print the joint/actuator table")
    common(show)
    show.add_argument("--json", action="store_true", help="machine-readable output")
    show.set_defaults(func=_show)

    mjcf = actions.add_parser("mjcf", help="write a self-contained MJCF (plain MjModel.from_xml_path loads it)")
    common(mjcf)
    self_collision(mjcf)
    mjcf.add_argument("-o", "--output", required=True, help="output .xml file")
    mjcf.add_argument("--no-floor", action="store_true", help="robot only, no ground plane")
    mjcf.set_defaults(func=_mjcf)

    urdf = actions.add_parser("urdf", help="write the URDF (same as the committed urdf/g1_inspire.urdf)")
    common(urdf)
    urdf.add_argument("-o", "--output", required=True, help="output .urdf file")
    urdf.set_defaults(func=_urdf)

    view = actions.add_parser("view", help="open the interactive MuJoCo viewer (needs a display)")
    common(view)
    self_collision(view)
    meshes(view)
    view.add_argument("--free", action="store_true", help="free-floating base (default: pelvis held in place; "
                      "the deploy gains alone cannot balance the robot)")
    view.set_defaults(func=_view)

    render = actions.add_parser("render", help="render the default pose to a PNG offscreen (MUJOCO_GL=egl/osmesa)")
    common(render)
    meshes(render)
    render.add_argument("-o", "--output", required=True, help="output .png file")
    render.add_argument("--width", type=int, default=640)
    render.add_argument("--height", type=int, default=720)
    render.add_argument("--azimuth", type=float, default=150.0, help="camera azimuth, degrees")
    render.add_argument("--elevation", type=float, default=-15.0, help="camera elevation, degrees")
    render.set_defaults(func=_render)


def _usage(parser: argparse.ArgumentParser) -> int:
    parser.print_help(sys.stderr)
    return 2


def _load(args):
    from robot_hoi.embodiment.config import load_embodiment

    return load_embodiment(args.embodiment, overrides=args.overrides)


def _collision_flag(args) -> bool | None:
    return None if args.self_collision is None else args.self_collision == "on"


def joint_table(cfg) -> list[dict]:
    """One row per hinge joint: actuated joints in actuator order, then passive (mimic) joints."""
    desc = cfg.description()
    hand_joints = {c.joint for hand in cfg.hands.values() for c in hand.channels}
    rows = []
    for index, act in enumerate(cfg.actuators):
        j = desc.joint(act.name)
        rows.append({
            "name": j.name, "kind": "hand" if j.name in hand_joints else "body", "actuator_index": index,
            "range": list(j.range), "effort": j.effort, "kp": act.kp, "kd": act.kd, "default": act.default,
            "action_scale": act.action_scale, "armature": j.armature, "damping": j.damping, "mimic": None,
        })
    for j in desc.passive_joints:
        rows.append({
            "name": j.name, "kind": "passive", "actuator_index": None, "range": list(j.range), "effort": j.effort,
            "kp": None, "kd": None, "default": None, "action_scale": None, "armature": j.armature,
            "damping": j.damping,
            "mimic": {"joint": j.mimic.joint, "multiplier": j.mimic.multiplier, "offset": j.mimic.offset},
        })
    return rows


def _show(args) -> int:
    cfg = _load(args)
    rows = joint_table(cfg)
    desc = cfg.description()
    if args.json:
        print(json.dumps({
            "embodiment": cfg.name, "control_dt": cfg.control_dt, "physics_dt": cfg.physics_dt,
            "total_mass_kg": desc.total_mass, "num_actuators": len(cfg.actuators), "joints": rows,
        }, indent=1))
        return 0
    from rich.table import Table

    from robot_hoi.utils.console import table_console

    table = Table(title=f"{cfg.name}: {len(cfg.actuators)} actuators, {len(desc.passive_joints)} passive joints, "
                  f"{desc.total_mass:.3f} kg, physics dt {cfg.physics_dt * 1e3:.2f} ms x {cfg.decimation}")
    for column in ("#", "joint", "kind", "range (rad)", "effort", "kp", "kd", "default", "scale", "armature"):
        table.add_column(column, justify="left" if column in ("joint", "kind") else "right")

    def fmt(x, spec="g"):
        return "" if x is None else format(x, spec)

    for r in rows:
        kind = r["kind"] if r["mimic"] is None else f"passive = {r['mimic']['multiplier']:g} x {r['mimic']['joint']}"
        table.add_row(fmt(r["actuator_index"]), r["name"], kind, f"[{r['range'][0]:.3f}, {r['range'][1]:.3f}]",
                      fmt(r["effort"]), fmt(r["kp"]), fmt(r["kd"]), fmt(r["default"]), fmt(r["action_scale"]),
                      fmt(r["armature"], ".4g"))
    table_console().print(table)
    return 0


def _mjcf(args) -> int:
    from robot_hoi.embodiment.mjcf import write_mjcf

    cfg = _load(args)
    path = write_mjcf(cfg, args.output, self_collision=_collision_flag(args), floor=not args.no_floor)
    print(f"wrote {path}")
    return 0


def _urdf(args) -> int:
    from robot_hoi.embodiment.urdf import write_urdf

    path = write_urdf(_load(args), args.output)
    print(f"wrote {path}")
    return 0


def _view(args) -> int:
    from robot_hoi.embodiment.render import view

    view(_load(args), meshes=args.meshes, fixed_base=not args.free, self_collision=_collision_flag(args))
    return 0


def _render(args) -> int:
    from robot_hoi.embodiment.render import render_png

    if args.width < 16 or args.height < 16:
        from robot_hoi.errors import UserError

        raise UserError(f"--width/--height must be at least 16 pixels, got {args.width}x{args.height}")
    path = render_png(_load(args), args.output, width=args.width, height=args.height, meshes=args.meshes,
                      azimuth=args.azimuth, elevation=args.elevation)
    print(f"wrote {path}")
    return 0
