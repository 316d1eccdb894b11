"""The ``settler`` command line.

Subcommands are listed in :data:`COMMANDS` (name -> (add_arguments, run, help)). The engines' commands live in the
engines (``popbal/cli.py``, ``fulldem/cli.py``) and are named in :data:`ENGINES`; this shared layer imports an engine
only when its command runs, so ``settler --version``, ``info`` and ``cases`` load neither. The analysis commands
(``figures``, ``compare``, ``calibrate``, ``sweep``, ``report``) are registered the same way, in :data:`TOOLS`, by the
name of their module in ``analysis/``: the shared layer imports no analysis module either.
"""

from __future__ import annotations

import argparse
import importlib
import os
import shlex
import sys

from . import __version__
from .errors import CaseError, OutputError
from .paths import DATA_DIR, preset_names

# settler.cases (Numba, through the physics) and settler.output (pandas) are imported by the commands that use them,
# so that `settler --help` and `settler COMMAND --help` start in well under a second (benchmarks/bench_startup.py).

def _case_help() -> str:
    names = ", ".join(preset_names()) or f"none found in {DATA_DIR / 'cases'}"  # a broken installation: the
    return f"a preset name ({names}) or a path to a case TOML file"  # commands still start, a case load says so

OVERRIDE_HELP = "section.key=value overrides of the case, e.g. slag.viscosity_reference=0.3 coalescence.enabled=false"


def _add_case_arguments(parser):
    parser.add_argument("case", help=_case_help())
    parser.add_argument("overrides", nargs="*", metavar="section.key=value",
                        help=OVERRIDE_HELP + " (before or after the options)")


def is_override(token: str) -> bool:
    """Whether a command-line word is a ``section.key=value`` override (not an option)."""
    return "=" in token and not token.startswith("-")


# ---------------------------------------------------------------------------------------------------------- info
def _info_arguments(parser):
    _add_case_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print the resolved case and derived numbers as JSON")


def _info(args) -> int:
    from .cases import load_case
    from .derived import as_records, derived_numbers, format_numbers
    from .output import to_json

    case = load_case(args.case, args.overrides)
    warn_implausible(case, "info")
    numbers = derived_numbers(case)
    if args.json:
        print(to_json({"case": case.to_dict(), "derived": as_records(numbers)}))
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
    from .cases import SCHEMA

    lines = []
    for section, fields in SCHEMA.items():
        lines += [f"### [{section}]", "", "| key | unit | allowed | meaning |", "|---|---|---|---|"]
        for key, field in fields.items():
            lines.append(f"| `{key}` | {field.unit or '–'} | {field.allowed()}{' (optional)' if field.optional else ''} "
                         f"| {field.doc} |")
        lines.append("")
    return "\n".join(lines)


def _cases(args) -> int:
    from .cases import list_presets, load_case

    if args.schema:
        print(schema_markdown())
        return 0
    for name in list_presets():
        case = load_case(name)
        print(f"{name:<10s} {case.case.description}")
    return 0


# ------------------------------------------------------------------------------------------------------- figures
def warn_implausible(case, command):
    """Print the case's plausibility warnings (values far outside what the laws were made for) to stderr."""
    from .derived import plausibility_warnings

    for text in plausibility_warnings(case):
        print(f"settler {command}: warning: {text}", file=sys.stderr)


def _engine(module_name):
    """(add_arguments, run) of an engine's command module, imported only when its command is used: the module has
    ``add_arguments(parser)`` (its options beyond CASE and the overrides) and ``main(args)`` (the exit status)."""
    def add_arguments(parser):
        _add_case_arguments(parser)
        importlib.import_module(module_name).add_arguments(parser)

    def run(args):
        return importlib.import_module(module_name).main(args)

    return add_arguments, run


def _tool(module_name):
    """(add_arguments, run) of an analysis command module, imported only when its command is used: the module has
    ``add_arguments(parser)`` (all its arguments) and ``main(args)`` (the exit status). Unlike an engine's, the
    command takes no case argument of its own."""
    def add_arguments(parser):
        importlib.import_module(module_name).add_arguments(parser)

    def run(args):
        return importlib.import_module(module_name).main(args)

    return add_arguments, run


#: The subcommands: name -> (add_arguments, run, help). The engines register their command modules here by name;
#: the shared layer imports none of them until its command is chosen.
ENGINES = {"reduced": ("popbal.cli", "run the reduced population-balance model (popbal) of a case"),
           "full": ("fulldem.cli", "run the coupled CFD-DEM engine (fulldem) on a case")}
#: The analysis commands (package analysis/), imported the same way: name -> (module, help).
TOOLS = {"compare": ("analysis.compare", "compare a full run with a reduced run column by column"),
         "calibrate": ("analysis.calibrate", "fit the reduced model's closures to the stored reference runs"),
         "sweep": ("analysis.sweep", "run the reduced model over a grid or a sampled design of case keys"),
         "report": ("analysis.report", "execute a report notebook from reports/ and write it as .ipynb and HTML"),
         "figures": ("analysis.figures", "draw the seed paper's figures from a run folder as PNGs")}
COMMANDS = {
    "info": (_info_arguments, _info, "print a resolved case and its derived numbers"),
    "cases": (_cases_arguments, _cases, "list the case presets, or print the case-file reference"),
    **{name: (*_engine(module), text) for name, (module, text) in ENGINES.items()},
    **{name: (*_tool(module), text) for name, (module, text) in TOOLS.items()},
}


DEBUG_HELP = "show the Python traceback of an error instead of the one-line message"


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser; with ``only``, the other subcommands are listed but their arguments (and engines) not loaded."""
    parser = argparse.ArgumentParser(
        prog="settler", description="Matte-droplet settling in copper flash-smelting settlers: CFD-DEM (full) and "
                                    "population-balance (reduced) models sharing one set of droplet physics.")
    parser.add_argument("--version", action="version", version=f"settler {__version__}")
    parser.add_argument("--debug", action="store_true", help=DEBUG_HELP)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (add_arguments, _, help_text) in COMMANDS.items():
        command = sub.add_parser(name, help=help_text, description=help_text)
        if only is None or name == only:
            add_arguments(command)
        command.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=DEBUG_HELP)
    return parser


def parse(argv):
    """Parse ``argv``; overrides (``section.key=value``) may come before or after the options."""
    parser = build_parser(only=next((a for a in argv if a in COMMANDS), ""))
    args, extra = parser.parse_known_args(argv)
    stray = [token for token in extra if not is_override(token) or not hasattr(args, "overrides")]
    if stray:
        parser.error("unrecognized arguments: " + " ".join(stray)
                     + ("" if hasattr(args, "overrides") else f" ('settler {args.command}' takes no overrides)"))
    if extra:
        args.overrides = list(args.overrides) + extra
    return args


def main(argv=None) -> int:
    """Run the ``settler`` command; returns the exit status: 0 done, 2 refused input (case, option, output folder),
    3 a run that failed, 128 + N stopped by signal N after saving (130 Ctrl-C, 143 SIGTERM), 1 an internal error."""
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse(argv)
    args.command_line = "settler " + " ".join(shlex.quote(a) for a in argv)
    where = f"settler {args.command}"
    try:
        return COMMANDS[args.command][1](args)
    except (CaseError, OutputError) as exc:
        if args.debug:
            raise
        print(f"{where}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        if args.debug:
            raise
        print(f"{where}: interrupted (no checkpoint was written: the run had not started its steps, or a "
              "second Ctrl-C stopped it at once)", file=sys.stderr)
        return 130
    except MemoryError:
        if args.debug:
            raise
        print(f"{where}: error: out of memory; use a coarser grid or fewer outputs", file=sys.stderr)
        return 3
    except BrokenPipeError:  # the reader of our output went away (`settler info simple | head`): stop quietly
        try:  # and let nothing more be written to the closed pipe at exit
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (AttributeError, ValueError, OSError):
            pass
        return 141
    except OSError as exc:
        if args.debug:
            raise
        print(f"{where}: error: {exc.filename or ''}{': ' if exc.filename else ''}{exc.strerror or exc}",
              file=sys.stderr)
        return 3
    except Exception as exc:  # a bug: say so in one line; --debug shows where
        if args.debug:
            raise
        print(f"{where}: internal error: {type(exc).__name__}: {exc} (this is a bug in settler; please report it "
              "with the command line; --debug shows the traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
