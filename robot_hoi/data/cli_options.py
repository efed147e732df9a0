"""The clip-loading flags every command that reads clips shares, so they are spelled and mean the same everywhere.

    --objects DIR   where `<object>/` folders live (mesh, URDF or sample points; default <clip dir>/../objects)
    --repair        interpolate NaN/inf frames and one-frame rotation glitches instead of failing

Only argparse here (no numpy), so `robot-hoi --help` stays fast. `clip_options(args)` gives the keyword arguments
of `robot_hoi.data.clip.load_clip`; training records them in task.json so later commands load the same clips.
"""

from __future__ import annotations

import argparse
from pathlib import Path

OBJECTS_HELP = ("folder of object folders <name>/ holding <name>.obj, <name>.urdf or sample_points.npy "
                "(default: <clip folder>/../objects; with none of them the object is a box estimated from the clip)")
REPAIR_HELP = "interpolate frames holding NaN/inf and one-frame root/object rotation glitches instead of failing"


def add_clip_options(parser: argparse.ArgumentParser, *aliases: str) -> None:
    """--objects DIR (plus any old spellings in `aliases`) and --repair."""
    parser.add_argument("--objects", *aliases, dest="objects", metavar="DIR", default=None, help=OBJECTS_HELP)
    parser.add_argument("--repair", action="store_true", help=REPAIR_HELP)


def clip_options(args: argparse.Namespace, recorded: dict | None = None) -> dict:
    """load_clip keyword arguments from the flags; flags not given fall back to `recorded` (a task.json's)."""
    options = dict(recorded or {})
    if getattr(args, "objects", None):
        options["objects_dir"] = str(Path(args.objects).resolve())
    if getattr(args, "repair", False):
        options["repair_missing"] = True
    return options
