"""``settler full CASE [section.key=value ...] --out DIR``: run the CFD-DEM engine on a case.

Registered in :data:`settler.cli.ENGINES`; the case arguments (CASE and overrides) are added there, the rest here.
A thin wrapper of the Python API (:func:`fulldem.setup`, :func:`fulldem.run`).
"""

from __future__ import annotations

import sys

from settler.arguments import seconds


def add_arguments(parser):
    """Options of ``settler full`` beyond CASE and the overrides."""
    parser.add_argument("--out", required=True, metavar="DIR",
                        help="output folder (created if missing; a folder holding another run is refused unless "
                             "--overwrite or --resume is given)")
    parser.add_argument("--end-time", type=seconds("--end-time"), metavar="SECONDS",
                        help="simulated time to stop at [s] (default: the case's fulldem.end_time)")
    parser.add_argument("--resume", action="store_true",
                        help="continue the run in DIR from its checkpoint.npz (written every "
                             "fulldem.checkpoint_interval of wall time, at the end, and on Ctrl-C or SIGTERM); "
                             "only with the same case")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace the run files of another run in DIR (without it, such a folder is refused)")
    parser.add_argument("--droplets", metavar="CSV",
                        help="initial droplets: CSV with a header line and columns x, y, z, diameter [, density] "
                             "in SI units")
    parser.add_argument("--no-feed", action="store_true", help="switch the droplet feed off")
    parser.add_argument("--quiet", action="store_true", help="no progress line")


def main(args) -> int:
    """Run ``settler full``: 0 done, 2 refused input (RunRefused: an end time, a droplet list, an occupied output
    folder, a checkpoint of another case; a bad case is reported by settler.cli), 3 a run that failed, 128 + N
    stopped by signal N after saving."""
    import fulldem
    from settler.cases import load_case
    from settler.cli import warn_implausible

    case = load_case(args.case, args.overrides)
    warn_implausible(case, "full")
    try:
        fulldem.run(fulldem.setup(case, droplets=args.droplets, feed=False if args.no_feed else None), args.out,
                    end_time=args.end_time, resume=args.resume, overwrite=args.overwrite, progress=not args.quiet,
                    command=getattr(args, "command_line", None))
    except fulldem.RunInterrupted as exc:
        print(f"settler full: {exc}", file=sys.stderr)
        return 128 + exc.signal_number
    except fulldem.RunRefused as exc:
        print(f"settler full: error: {exc}", file=sys.stderr)
        return 2
    except fulldem.RunError as exc:
        print(f"settler full: error: {exc}", file=sys.stderr)
        return 3
    return 0
