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
turning share) are left out for those runs, as the hierarchy's transport level has no bottom layer. What a set fits
is not measured and needs ``--set``: under ``zones_core`` popbal.plume_core_radius, channel_radius_factor and
bottom_layer_factor (measured at the fit's radii); under ``zones_stir`` also bottom_turning_share (its form is the
set's, 'uniform'), while the channel's collision radii and the outer stirring come measured; under ``zones_scale``
also popbal.plume_core_exponent.

``--bands`` adds, per run, where each model holds its matte and where it merges, band by band
(:func:`zone_bands`): the full run's plume core and return flow (``plume_zones.csv``) and merges under the inlet and
elsewhere (``collisions_by_height.csv``) beside popbal's channel, outer zone and layers over the same window.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

#: Keys that need a bottom layer, which the coalescence-off runs are probed without (their floors fill).
BOTTOM_KEYS = ("popbal.bottom_layer_factor", "popbal.bottom_turning_share", "popbal.bottom_turning_form",
               "popbal.bottom_drain_coefficient", "popbal.bottom_shear_coefficient",
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


def _run_values(case_file, fixed: dict) -> dict:
    """The overrides a probe gives one run: ``fixed`` less the bottom layer's keys for a coalescence-off run."""
    from settler.cases import load_case

    if load_case(case_file).coalescence.enabled:
        return dict(fixed)
    return {k: v for k, v in fixed.items() if k not in BOTTOM_KEYS}


#: The column a probe adds to the targets': the matte held in the slag [kg] (time series column), window means.
HELD = "mass_in_slag"


def probe(runs, overrides: dict, registry, reference_dir="data/reference", closures: str = "zones_line",
          report=None) -> dict[str, dict[str, float]]:
    """{run: {column: reduced / full - 1}} for popbal on each stored run under ``closures``' measured values and
    ``overrides`` ({dotted key: value}), the columns :data:`TARGET_COLUMNS` and :data:`HELD`, the matte both hold
    in the slag (not fitted: the inventory a count and a mean diameter can be right without); ``report(run, errors,
    seconds)`` is called after each run. ValueError for a registered hold-out (nothing is run then)."""
    from analysis.calibration.fit import reduced_series
    from analysis.evidence import steady_means
    from settler.output import read_time_series
    from analysis.calibration.hierarchy import measured_closures
    from analysis.calibration.registry import refuse_holdouts
    from analysis.calibration.targets import TARGET_COLUMNS, load_target, seed_scatter, window_means

    refuse_holdouts(runs, registry, "a probe", reference_dir)
    fixed = {**measured_closures(registry, reference_dir, closures)["fixed"], **overrides}
    seed = seed_scatter(reference_dir)
    out = {}
    for run in runs:
        case_file = Path(reference_dir) / run / "case.toml"
        values = _run_values(case_file, fixed)
        start = time.perf_counter()
        target = load_target(run, reference_dir, seed)
        series = reduced_series(target, case_file, {}, values)
        got = window_means(series, target.window)
        out[run] = {c: got[c] / target.means[c] - 1.0 for c in TARGET_COLUMNS}
        full = read_time_series(case_file.parent / "timeseries.csv")
        held = (steady_means(series, [HELD], *target.window)[HELD], steady_means(full, [HELD], *target.window)[HELD])
        out[run][HELD] = held[0] / held[1] - 1.0
        if report:
            report(run, out[run], time.perf_counter() - start)
    return out


#: Columns of :func:`zone_bands`: name -> (unit, meaning). Loads per metre of height, merges per second, all over
#: the window of the run's stored diagnostic tables.
BAND_COLUMNS = {
    "z": ("m", "the band's centre height (settler.output.PROFILE_BANDS equal bands)"),
    "full_core_load": ("m^3/m", "full run: droplet volume inside the plume's half-volume radius and its skirt "
                                "(plume_zones.csv core + skirt)"),
    "full_return_load": ("m^3/m", "full run: droplet volume in the return flow (plume_zones.csv)"),
    "full_held": ("-", "full run: droplets in the band (collisions_by_height.csv)"),
    "full_merges_inlet": ("1/s", "full run: merges under the inlet (collisions_by_height.csv)"),
    "full_merges_elsewhere": ("1/s", "full run: merges elsewhere"),
    "popbal_channel_load": ("m^3/m", "popbal: droplet volume in the channel zone's cells of the band"),
    "popbal_outer_load": ("m^3/m", "popbal: droplet volume in the outer zone's cells (the return flow)"),
    "popbal_layer_load": ("m^3/m", "popbal: the roof or bottom layer's droplet volume over the band's height, in the "
                                   "band that holds the layer's cell (the top one, the bottom one)"),
    "popbal_held": ("-", "popbal: droplets in the band, every zone (a layer's in its cell's band)"),
    "popbal_merges_channel": ("1/s", "popbal: merges in the channel zone's cells of the band"),
    "popbal_merges_outer": ("1/s", "popbal: merges in the outer zone's cells of the band"),
    "popbal_merges_layer": ("1/s", "popbal: merges in the roof or bottom layer (in its cell's band)"),
}

#: popbal's output interval for :func:`zone_bands` [s]: the stored tables' windows start and end on whole seconds.
BAND_OUTPUT_INTERVAL = 0.5


def zone_bands(run: str, overrides: dict, registry, reference_dir="data/reference",
               closures: str = "zones_line"):
    """One run's :data:`BAND_COLUMNS` table (pandas DataFrame, one row per height band, SI units): where the full run
    and popbal (under ``closures``' measured values and ``overrides``, as :func:`probe` runs it) hold their droplets'
    volume, how many, and where they merge, over the window of the run's stored ``collisions_by_height.csv`` and
    ``plume_zones.csv`` (which can start earlier than the calibration's scored window): the full run's figures are
    those tables' window means, popbal's the means over its outputs in the same window (loads and droplets) and its
    merges between the window's ends. ValueError for a registered hold-out, a run without either table (a
    coalescence-off run has no collisions table) or tables of different windows; nothing is run then."""
    import numpy as np
    import pandas as pd

    import popbal
    from analysis.band_efficiency import COLLISIONS_FILE
    from analysis.calibration.hierarchy import measured_closures
    from analysis.calibration.registry import refuse_holdouts
    from analysis.files import read_window_header
    from analysis.plume_zones import PLUME_ZONES_FILE
    from popbal.driver import band_cells
    from popbal.model import BOTTOM, CHANNEL, OUTER, ROOF
    from settler.cases import NO_CALIBRATION, load_case

    refuse_holdouts([run], registry, "a probe", reference_dir)
    folder = Path(reference_dir) / run
    for name in (PLUME_ZONES_FILE, COLLISIONS_FILE):
        if not (folder / name).is_file():
            raise ValueError(f"{folder / name}: not stored; the band table needs the run's {name}")
    start, end = read_window_header(folder / COLLISIONS_FILE)["window"]
    if read_window_header(folder / PLUME_ZONES_FILE)["window"] != (start, end):
        raise ValueError(f"{folder}: {PLUME_ZONES_FILE} and {COLLISIONS_FILE} cover different windows; the band "
                         "table needs one")
    zones = pd.read_csv(folder / PLUME_ZONES_FILE, comment="#")
    collisions = pd.read_csv(folder / COLLISIONS_FILE, comment="#")
    case_file = folder / "case.toml"
    values = _run_values(case_file, {**measured_closures(registry, reference_dir, closures)["fixed"], **overrides})
    case = load_case(case_file, {"case.calibration": NO_CALIBRATION, **values, "popbal.end_time": end,
                                 "popbal.output_interval": BAND_OUTPUT_INTERVAL})
    result = popbal.run(popbal.setup(case), progress=False)
    model, arrays = result.model, result.arrays
    times = np.asarray(arrays["time"])
    inside = (times >= start - 1e-9) & (times <= end + 1e-9)
    first, last = np.flatnonzero(inside)[[0, -1]]
    if abs(times[first] - start) > 1e-6 or abs(times[last] - end) > 1e-6:
        raise ValueError(f"{folder}: popbal's outputs every {BAND_OUTPUT_INTERVAL} s do not fall on the window "
                         f"{start}-{end} s")
    area = np.asarray(arrays["zone_area"])[:, None]
    number = np.asarray(arrays["number_density"])[inside]  # (T, Z, J, K)
    volume = (number * np.pi / 6.0 * np.nan_to_num(np.asarray(arrays["diameter"])[inside]) ** 3).sum(axis=-1)
    load = volume.mean(axis=0) * area  # (Z, J) m^3 per m of height in each zone's cells, window mean
    held = number.sum(axis=-1).mean(axis=0) * area  # (Z, J) droplets per m of height
    merges = (np.asarray(arrays["merges"])[last] - np.asarray(arrays["merges"])[first]) / (end - start)
    bands = band_cells(model.z, case.geometry.height)  # popbal's own bands (merges_by_height.csv's)
    height, dz = case.geometry.height / len(bands), model.cell_height
    top = len(model.z) - 1
    rows = []
    for b, (centre, cells) in enumerate(bands):
        # a layer's one cell is the top one (roof) or the bottom one: the layer is booked in that cell's band
        layers = [zone for zone, cell in ((ROOF, top), (BOTTOM, 0)) if cell in cells]
        rows.append({
            "z": centre,
            "full_core_load": float(zones["core_load"].iloc[b] + zones["skirt_load"].iloc[b]),
            "full_return_load": float(zones["return_load"].iloc[b]),
            "full_held": float(collisions["held"].iloc[b]),
            "full_merges_inlet": float(collisions["merges_under_inlet"].iloc[b]) / (end - start),
            "full_merges_elsewhere": float(collisions["merges_elsewhere"].iloc[b]) / (end - start),
            "popbal_channel_load": float(load[CHANNEL, cells].sum()) * dz / height,
            "popbal_outer_load": float(load[OUTER, cells].sum()) * dz / height,
            "popbal_layer_load": sum(float(load[zone].sum()) for zone in layers) * dz / height,
            "popbal_held": (float(held[[CHANNEL, OUTER]][:, cells].sum()) + sum(float(held[zone].sum())
                                                                              for zone in layers)) * dz,
            "popbal_merges_channel": float(merges[CHANNEL, cells].sum()),
            "popbal_merges_outer": float(merges[OUTER, cells].sum()),
            "popbal_merges_layer": sum(float(merges[zone].sum()) for zone in layers),
        })
    return pd.DataFrame(rows, columns=list(BAND_COLUMNS))


def _print_bands(run, table):
    print(f"  {run}: loads [cm^3/m] full core / return | popbal channel / outer / layer;  merges [1/s] full "
          "inlet / elsewhere | popbal channel / outer / layer;  droplets full | popbal")
    for _, r in table.iloc[::-1].iterrows():
        print(f"    z {r.z:6.3f} m  {1e6 * r.full_core_load:7.1f} / {1e6 * r.full_return_load:7.1f} | "
              f"{1e6 * r.popbal_channel_load:7.1f} / {1e6 * r.popbal_outer_load:7.1f} / "
              f"{1e6 * r.popbal_layer_load:7.1f};  {r.full_merges_inlet:7.0f} / {r.full_merges_elsewhere:6.0f} | "
              f"{r.popbal_merges_channel:7.0f} / {r.popbal_merges_outer:6.0f} / {r.popbal_merges_layer:7.0f};  "
              f"{r.full_held:7.0f} | {r.popbal_held:7.0f}", flush=True)


def main(argv=None) -> int:
    from analysis.calibration.hierarchy import CLOSURES
    from analysis.calibration.registry import RegistryError, load_registry
    from analysis.calibration.targets import TARGET_COLUMNS
    from settler.cases import CaseError, load_case

    parser = argparse.ArgumentParser(prog="python -m analysis.calibration.probe", description=(
        "popbal on training runs with a closure set's measured values and the values given, against the stored "
        "full runs: a line of relative errors per run (count, mean diameter, settling flux, axis velocity, and the "
        "matte held in the slag, which no fit takes)"))
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
    parser.add_argument("--bands", action="store_true",
                        help="after each run's line, where the full run and popbal hold their droplets' volume and "
                             "where they merge, band by band (runs popbal again for each run)")
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
    print("run".ljust(28) + " / ".join(c.replace("_", " ") for c in TARGET_COLUMNS)
          + "  (held matte, not fitted)  [%, reduced / full - 1]")

    def report(run, errors, seconds):
        print(f"{run:28s}" + " / ".join(f"{100 * errors[c]:+5.0f}" for c in TARGET_COLUMNS)
              + f"   ({100 * errors[HELD]:+5.0f})   ({seconds:.0f} s)", flush=True)
        if not args.bands:
            return
        if not load_case(Path(args.reference_dir) / run / "case.toml").coalescence.enabled:
            print(f"  {run}: no band table (coalescence off: the run stores no collisions_by_height.csv)")
            return
        _print_bands(run, zone_bands(run, overrides, registry, args.reference_dir, args.closures))

    try:
        probe(runs, overrides, registry, args.reference_dir, args.closures, report)
    except (ValueError, CaseError) as exc:
        print(f"probe: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
