"""The `drem` command.

One entry point; every subcommand lives in its own module and is imported only when it runs,
so `drem status` never pays for torch, pymunk or aws-cdk. A subcommand module exposes
`HELP: str`, `add_arguments(parser)` and `run(args) -> int`.
"""
from __future__ import annotations

import argparse
import copy
import importlib
import sys

from drem_local.app_source import use_app_source

SUBCOMMANDS: dict[str, str] = {
    "up": "drem_local.commands.up",
    "status": "drem_local.commands.status",
    "build": "drem_local.commands.build",
    "users": "drem_local.commands.users",
    "events": "drem_local.commands.events",
    "fleets": "drem_local.commands.fleets",
    "cars": "drem_local.commands.cars",
    "models": "drem_local.commands.models",
    "export": "drem_local.commands.export",
    "import": "drem_local.commands.import_",
    "league": "drem_local.commands.league",
    "aws": "drem_local.commands.aws",
    "car": "drem_cars.cli",
    "timer": "drem_cars.cli_timer",
    "sim": "drem_sim.cli",
    "train": "drem_sim.cli_train",
}


def _load(module_name: str):
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        return exc


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="drem", description="DeepRacer Event Manager")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module_name in SUBCOMMANDS.items():
        module = _load(module_name)
        if isinstance(module, ModuleNotFoundError):
            p = sub.add_parser(name, help=f"(unavailable: {module.name} is not installed)")
            p.set_defaults(_missing=module)
            continue
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        accept_options_after_action(p)
        p.set_defaults(_run=module.run)
    return parser


def accept_options_after_action(parser: argparse.ArgumentParser) -> None:
    """`drem events list --api URL` as well as `drem events --api URL list`: each option of a command is also
    accepted after its action. The copies default to SUPPRESS, so an option given before the action is kept."""
    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    options = [a for a in parser._actions if a.option_strings and not isinstance(a, argparse._HelpAction)]
    for subparsers in actions:
        for child in set(subparsers.choices.values()):
            taken = {s for a in child._actions for s in a.option_strings}
            for option in options:
                if taken.isdisjoint(option.option_strings):
                    twin = copy.copy(option)
                    twin.default, twin.required = argparse.SUPPRESS, False
                    child._add_action(twin)
            accept_options_after_action(child)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "_missing", None) is not None:
        print(f"drem {args.command}: needs the Python module {args._missing.name!r}; "
              "install the matching extra, e.g. pip install -e '.[sim,train,car]'", file=sys.stderr)
        return 2
    if getattr(args, "_run", None) is None:
        parser.print_help()
        return 2
    use_app_source()  # subcommands import chalicelib; it lives in functions/, not site-packages
    return int(args._run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
