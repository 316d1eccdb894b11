"""``settler reduced CASE [section.key=value ...] --out DIR``: run the reduced model of a case and write its outputs.

Registered in :data:`settler.cli.COMMANDS`; the case arguments (CASE and overrides) are added there, the rest here.
"""

from __future__ import annotations

import math
import sys

from settler.arguments import seconds

from .limits import MAX_OUTPUTS


def add_arguments(parser):
    """Options of ``settler reduced`` beyond CASE and the overrides."""
    parser.add_argument("--out", required=True, metavar="DIR",
                        help="output folder: timeseries.csv, distribution.npz, case.toml, metadata.json")
    parser.add_argument("--end-time", type=seconds("--end-time"), metavar="S",
                        help="simulated time to stop at [s], a finite number > 0 (default: popbal.end_time of the "
                             "case)")
    parser.add_argument("--output-interval", type=seconds("--output-interval"), metavar="S",
                        help="simulated time between outputs [s], a finite number > 0; at most "
                             f"{MAX_OUTPUTS} outputs (default: popbal.output_interval)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace the run files of another run in DIR (without it, such a folder is refused)")
    progress = parser.add_mutually_exclusive_group()
    progress.add_argument("--progress", action="store_true", default=None, help="print progress lines to stderr")
    progress.add_argument("--quiet", action="store_true",
                          help="no progress lines (default: they start once a run has taken 5 s)")


def main(args) -> int:
    """Run ``settler reduced``; CaseError is reported by settler.cli (exit status 2), and so are the refusals of
    run() (options out of range, too many outputs, arrays over popbal.limits.memory_limit())."""
    from settler.cases import case_with_overrides
    from settler.cli import warn_implausible
    from settler.output import prepare_output_folder

    from . import run, setup
    from .driver import check_run

    case = case_with_overrides(args.case, args.overrides)
    warn_implausible(case, "reduced")  # before the model is built: its closures may overflow on such a value
    model = setup(case)
    prepare_output_folder(args.out, overwrite=args.overwrite, create=False)  # refused before the run, created after
    progress = False if args.quiet else args.progress
    try:
        # the size checks first, so that their messages name the options rather than run()'s arguments
        check_run(model, args.end_time, args.output_interval, names=("--end-time", "--output-interval"))
        result = run(model, end_time=args.end_time, output_interval=args.output_interval, progress=progress)
    except ValueError as exc:
        print(f"settler reduced: error: {exc}", file=sys.stderr)
        return 2
    out = result.save(prepare_output_folder(args.out, overwrite=args.overwrite))
    last = result.timeseries.iloc[-1]
    fed = last["mass_fed"]
    share = (lambda m: f"{100 * m / fed:.3g} %") if fed > 0 else (lambda m: "-")
    mean = last["mean_diameter"]
    print(f"settler reduced {model.name}: {result.steps} steps, {last['time']:g} s simulated in "
          f"{result.wall_time:.2f} s wall")
    print(f"  droplets in slag {last['droplet_count']:.4g}, mean diameter "
          f"{'-' if math.isnan(mean) else f'{mean * 1e6:.4g} um'}; of the matte fed ({fed:.4g} kg): "
          f"settled {share(last['mass_settled'])}, in slag {share(last['mass_in_slag'])}, "
          f"lost {share(last['mass_lost'])}, FeS reacted {share(last['mass_reacted'])}")
    print(f"  outputs in {out}/ (timeseries.csv, distribution.npz, case.toml, metadata.json)")
    return 0
