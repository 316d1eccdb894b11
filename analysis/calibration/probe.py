"""Probe a closure set on the training runs: popbal with what a closure set measures (no level fitted) and the
values given, against the stored full runs' steady-window means (SI units inside; errors in %).

    python -m analysis.calibration.probe --closures zones_line --set popbal.channel_coefficient=1 ...
        [--runs demo_cell_25,deep_w005] [--reference-dir data/reference] [--registry data/calibration/holdouts.toml]

The questions the reduced-model guide asks of each closure ("with the measured radius, how far is the demo's feed
family?") are answered this way: the closure set's measured values (:func:`analysis.calibration.hierarchy.
measured_closures`: the collision level's efficiency, the radius or dilution law, the roof law and its kernel) with
``--set`` overrides on top, run on each named run (default: the registry's transport and whole levels), and a line
per run of the relative error reduced / full - 1 of the droplet count, mean diameter, settling flux and axis
velocity (:data:`analysis.calibration.targets.TARGET_COLUMNS`). A registered hold-out is refused, as the fit refuses
it (:func:`analysis.calibration.registry.refuse_holdouts`): a probe chooses closures, and no closure may be chosen
from a hold-out. Keys a coalescence-off run's case refuses without a bottom layer (the bottom layer's factor and its
turning share) are left out for those runs, as the hierarchy's transport level has no bottom layer.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

#: Keys that need a bottom layer, which the coalescence-off runs are probed without (their floors fill).
BOTTOM_KEYS = ("popbal.bottom_layer_factor", "popbal.bottom_turning_share", "popbal.bottom_drain_coefficient",
               "popbal.bottom_shear_coefficient",
               "popbal.bottom_lift_share", "popbal.bottom_lift_velocity_ratio")


def parse_setting(text: str) -> tuple[str, object]:
    """A --set item as the case overrides take it (settler.cases.parse_override: the value read as TOML, else a
    string), with ``none`` leaving the key unset (e.g. the dilution law a closure set measures, where the form given
    does not take it). CaseError where it is not section.key=value."""
    from settler.cases import CaseError, parse_override

    key, value = parse_override(text)
    if "." not in key:
        raise CaseError(f"--set {text!r}: allowed: section.key=value (e.g. popbal.channel_coefficient=1)")
    return key, None if value == "none" else value


def probe(runs, overrides: dict, registry, reference_dir="data/reference", closures: str = "zones_line",
          report=None) -> dict[str, dict[str, float]]:
    """{run: {column: reduced / full - 1}} for popbal on each stored run under ``closures``' measured values and
    ``overrides`` ({dotted key: value}); ``report(run, errors, seconds)`` is called after each run. ValueError for a
    registered hold-out (nothing is run then)."""
    from analysis.calibration.fit import reduced_means
    from analysis.calibration.hierarchy import measured_closures
    from analysis.calibration.registry import refuse_holdouts
    from analysis.calibration.targets import TARGET_COLUMNS, load_target, seed_scatter
    from settler.cases import load_case

    refuse_holdouts(runs, registry, "a probe")
    fixed = {**measured_closures(registry, reference_dir, closures)["fixed"], **overrides}
    seed = seed_scatter(reference_dir)
    out = {}
    for run in runs:
        case_file = Path(reference_dir) / run / "case.toml"
        values = dict(fixed)
        if not load_case(case_file).coalescence.enabled:
            for key in BOTTOM_KEYS:
                values.pop(key, None)
        start = time.perf_counter()
        target = load_target(run, reference_dir, seed)
        got = reduced_means(target, case_file, {}, values)
        out[run] = {c: got[c] / target.means[c] - 1.0 for c in TARGET_COLUMNS}
        if report:
            report(run, out[run], time.perf_counter() - start)
    return out


def main(argv=None) -> int:
    from analysis.calibration.hierarchy import CLOSURES
    from analysis.calibration.registry import RegistryError, load_registry
    from analysis.calibration.targets import TARGET_COLUMNS
    from settler.cases import CaseError

    parser = argparse.ArgumentParser(prog="python -m analysis.calibration.probe", description=(
        "popbal on training runs with a closure set's measured values and the values given, against the stored "
        "full runs: a line of relative errors per run (count, mean diameter, settling flux, axis velocity)"))
    parser.add_argument("--closures", default="zones_line", choices=tuple(CLOSURES),
                        help="the closure set whose measured values are taken (default zones_line)")
    parser.add_argument("--set", action="append", default=[], metavar="popbal.KEY=VALUE",
                        help="a case override on top of them (repeatable), e.g. popbal.channel_coefficient=1; "
                             "VALUE none leaves the key unset")
    parser.add_argument("--runs", default=None,
                        help="comma-separated stored runs (default: the registry's transport and whole levels)")
    parser.add_argument("--reference-dir", default="data/reference", help="folder of the stored runs")
    parser.add_argument("--registry", default="data/calibration/holdouts.toml",
                        help="the calibration's registry: its levels give the default runs, its hold-outs are "
                             "refused")
    args = parser.parse_args(argv)
    try:
        overrides = dict(parse_setting(item) for item in args.set)
    except CaseError as exc:
        print(f"probe: {exc}", file=sys.stderr)
        return 2
    try:
        registry = load_registry(args.registry)
    except (OSError, RegistryError) as exc:
        print(f"probe: --registry {args.registry}: {exc}", file=sys.stderr)
        return 2
    levels = registry.levels
    runs = args.runs.split(",") if args.runs else list(dict.fromkeys([*levels.get("whole", ()),
                                                                       *levels.get("transport", ())]))
    missing = [r for r in runs if not (Path(args.reference_dir) / r / "case.toml").is_file()]
    if missing:
        print(f"probe: --runs: {', '.join(missing)} not stored in {args.reference_dir}", file=sys.stderr)
        return 2
    print("run".ljust(28) + " / ".join(c.replace("_", " ") for c in TARGET_COLUMNS) + "  [%, reduced / full - 1]")

    def report(run, errors, seconds):
        print(f"{run:28s}" + " / ".join(f"{100 * e:+5.0f}" for e in errors.values()) + f"   ({seconds:.0f} s)",
              flush=True)

    try:
        probe(runs, overrides, registry, args.reference_dir, args.closures, report)
    except (ValueError, CaseError) as exc:
        print(f"probe: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
