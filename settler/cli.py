"""The ``settler`` command line.

Subcommands register themselves in :data:`COMMANDS` (name -> (add_arguments, run)); the engines add ``full`` and
``reduced`` the same way.
"""

from __future__ import annotations

import argparse
import json
import sys

from . import __version__
from .cases import SCHEMA, CaseError, list_presets, load_case

CASE_HELP = ("a preset name (" + ", ".join(list_presets()) + ") or a path to a case TOML file")
OVERRIDE_HELP = "section.key=value overrides of the case, e.g. slag.viscosity_reference=0.3 coalescence.enabled=false"


def _add_case_arguments(parser):
    parser.add_argument("case", help=CASE_HELP)
    parser.add_argument("overrides", nargs="*", metavar="section.key=value", help=OVERRIDE_HELP)


# ---------------------------------------------------------------------------------------------------------- info
def _info_arguments(parser):
    _add_case_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print the resolved case and derived numbers as JSON")


def _info(args) -> int:
    from .derived import as_records, derived_numbers, format_numbers

    case = load_case(args.case, args.overrides)
    numbers = derived_numbers(case)
    if args.json:
        print(json.dumps({"case": case.to_dict(), "derived": as_records(numbers)}, indent=1))
    else:
        print(case.to_toml())
        print("# derived numbers")
        print(format_numbers(numbers))
    return 0


# --------------------------------------------------------------------------------------------------------- cases
def _cases_arguments(parser):
    parser.add_argument("--schema", action="store_true",
                        help="print the case-file reference (every key, type, unit, allowed values) as Markdown")


def schema_markdown() -> str:
    """The case-file reference, generated from settler.cases.SCHEMA."""
    lines = []
    for section, fields in SCHEMA.items():
        lines += [f"### [{section}]", "", "| key | unit | allowed | meaning |", "|---|---|---|---|"]
        for key, field in fields.items():
            lines.append(f"| `{key}` | {field.unit or '–'} | {field.allowed()}{' (optional)' if field.optional else ''} "
                         f"| {field.doc} |")
        lines.append("")
    return "\n".join(lines)


def _cases(args) -> int:
    if args.schema:
        print(schema_markdown())
        return 0
    for name in list_presets():
        case = load_case(name)
        print(f"{name:<10s} {case.case.description}")
    return 0


# ------------------------------------------------------------------------------------------------------- reduced
def _reduced_arguments(parser):
    from popbal.cli import add_arguments

    _add_case_arguments(parser)
    add_arguments(parser)


def _reduced(args) -> int:
    from popbal.cli import main as reduced_main

    return reduced_main(args)


# ---------------------------------------------------------------------------------------------------------- full
def _full_arguments(parser):
    _add_case_arguments(parser)
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    parser.add_argument("--end-time", type=float, metavar="SECONDS",
                        help="simulated time to stop at [s] (default: the case's fulldem.end_time)")
    parser.add_argument("--resume", action="store_true", help="continue from DIR/checkpoint.npz")
    parser.add_argument("--droplets", metavar="CSV",
                        help="initial droplets: CSV with columns x, y, z, diameter [, density] in SI units")
    parser.add_argument("--no-feed", action="store_true", help="switch the droplet feed off")
    parser.add_argument("--quiet", action="store_true", help="no progress line")


def _full(args) -> int:
    from fulldem.run import RunError, run_case

    case = load_case(args.case, args.overrides)
    try:
        run_case(case, args.out, end_time=args.end_time, resume=args.resume, droplets=args.droplets,
                 feed=False if args.no_feed else None, progress=not args.quiet)
    except RunError as exc:
        print(f"settler full: error: {exc}", file=sys.stderr)
        return 3
    return 0


COMMANDS = {
    "info": (_info_arguments, _info, "print a resolved case and its derived numbers"),
    "cases": (_cases_arguments, _cases, "list the case presets, or print the case-file reference"),
    "reduced": (_reduced_arguments, _reduced, "run the reduced population-balance model (popbal) of a case"),
    "full": (_full_arguments, _full, "run the coupled CFD-DEM engine (fulldem) on a case"),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="settler", description="Matte-droplet settling in copper flash-smelting settlers: CFD-DEM (full) and "
                                    "population-balance (reduced) models sharing one set of droplet physics.")
    parser.add_argument("--version", action="version", version=f"settler {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (add_arguments, _, help_text) in COMMANDS.items():
        add_arguments(sub.add_parser(name, help=help_text, description=help_text))
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return COMMANDS[args.command][1](args)
    except CaseError as exc:
        print(f"settler {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
