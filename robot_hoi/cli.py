"""`robot-hoi` command line.

Each area registers its own subcommand from a small `cli.py` whose `register(subparsers)` only builds argparse
parsers: heavy imports (torch, mujoco) happen inside the handlers, so `robot-hoi --help` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import sys

# subcommand -> module with register(subparsers). Order is the pipeline order shown in --help.
COMMAND_MODULES = {
    "data": "robot_hoi.commands.data",
    "model": "robot_hoi.commands.model",
    "retarget": "robot_hoi.commands.retarget",
    "train": "robot_hoi.commands.train",
    "eval": "robot_hoi.commands.eval",
    "compare": "robot_hoi.commands.compare",
    "results": "robot_hoi.commands.results",
    "curve": "robot_hoi.commands.curve",
    "play": "robot_hoi.commands.play",
    "export": "robot_hoi.commands.export",
    "deploy": "deploy.cli",
    "sim2sim": "sim2sim.cli",
}


def _register_unbuilt(subparsers, name: str) -> None:
    """A subcommand whose code is not in this build: it says so and exits non-zero, never fakes success."""

    def handler(args: argparse.Namespace) -> int:
        print(f"robot-hoi {name}: not built yet in this version of robot-hoi.", file=sys.stderr)
        return 3

    p = subparsers.add_parser(name, help=f"({name}: not built yet)", add_help=True)
    p.add_argument("rest", nargs=argparse.REMAINDER)
    p.set_defaults(func=handler)


class _ShowDefaults(argparse.HelpFormatter):
    """Appends "(default: X)" to an option's help unless the help already names its default or there is none."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        unset = action.default is None or action.default is False or action.default in ([], argparse.SUPPRESS)
        if action.option_strings and not unset and "default" not in text.lower():
            text += (" " if text else "") + "(default: %(default)s)"
        return text


class _ShowDefaultsRaw(_ShowDefaults, argparse.RawDescriptionHelpFormatter):
    pass


def _show_defaults(parser: argparse.ArgumentParser) -> None:
    """Every (sub)command's --help lists its defaults, whichever module built the parser."""
    raw = issubclass(parser.formatter_class, argparse.RawDescriptionHelpFormatter)
    parser.formatter_class = _ShowDefaultsRaw if raw else _ShowDefaults
    for action in parser._actions:  # argparse keeps subcommands only here
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                _show_defaults(sub)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="robot-hoi",
        description="Human-object-interaction MoCap -> Unitree G1 + Inspire hand policies.",
    )
    parser.add_argument("--version", action="store_true", help="print the version and exit")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module_name in COMMAND_MODULES.items():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            # Only a missing command module means "not built"; a broken import inside it must surface.
            if exc.name is not None and module_name.startswith(exc.name):
                _register_unbuilt(subparsers, name)
                continue
            raise
        module.register(subparsers)
    _show_defaults(parser)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.version:
        from robot_hoi import __version__

        print(__version__)
        return 0
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # user-facing errors carry `user_error`; anything else is a bug and keeps its traceback
        if getattr(exc, "user_error", False):
            print(f"robot-hoi {args.command}: error: {exc}", file=sys.stderr)
            return 2
        raise


if __name__ == "__main__":
    sys.exit(main())
