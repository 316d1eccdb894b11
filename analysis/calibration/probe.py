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


#: Columns of :func:`zone_bands`: name -> (unit, meaning). Loads per metre of height, merges per second.
BAND_COLUMNS = {
    "z": ("m", "the band's centre height (settler.output.PROFILE_BANDS equal bands)"),
    "full_core_load": ("m^3/m", "full run: droplet volume inside the plume's half-volume radius and its skirt "
                                "(plume_zones.csv core + skirt), window mean"),
    "full_return_load": ("m^3/m", "full run: droplet volume in the return flow (plume_zones.csv), window mean"),
    "full_held": ("-", "full run: droplets in the band, window mean (collisions_by_height.csv)"),
    "full_merges_inlet": ("1/s", "full run: merges under the inlet over the window (collisions_by_height.csv)"),
    "full_merges_elsewhere": ("1/s", "full run: merges elsewhere over the window"),
    "popbal_channel_load": ("m^3/m", "popbal: droplet volume in the channel zone at the window's end"),
    "popbal_outer_load": ("m^3/m", "popbal: droplet volume in the outer zone (the return flow) at the window's end"),
    "popbal_layer_load": ("m^3/m", "popbal: the roof layer's (top band) or bottom layer's (bottom band) droplet volume "
                                   "over the band's height, at the window's end"),
    "popbal_held": ("-", "popbal: droplets in the band's cells of every zone (the layers' in the top and bottom bands), "
                         "at the window's end"),
    "popbal_merges_channel": ("1/s", "popbal: merges in the channel zone's cells of the band over the window"),
    "popbal_merges_outer": ("1/s", "popbal: merges in the outer zone's cells of the band over the window"),
    "popbal_merges_layer": ("1/s", "popbal: merges in the roof layer (top band) or bottom layer (bottom band)"),
}


def zone_bands(run: str, overrides: dict, registry, reference_dir="data/reference",
               closures: str = "zones_line"):
    """One run's :data:`BAND_COLUMNS` table (pandas DataFrame, one row per height band, SI units): where the full run
    and popbal (under ``closures``' measured values and ``overrides``, as :func:`probe` runs it, to the end of the
    run's steady window) hold their droplets' volume and where they merge. popbal's merges are its ``merges`` over
    the window (outputs every window / 20), its loads the state at the window's end; the full run's are the stored
    tables' window means. ValueError for a registered hold-out, or a run without plume_zones.csv or
    collisions_by_height.csv (nothing is run then)."""
    import numpy as np
    import pandas as pd

    import popbal
    from analysis.band_efficiency import COLLISIONS_FILE
    from analysis.calibration.hierarchy import measured_closures
    from analysis.calibration.registry import refuse_holdouts
    from analysis.calibration.targets import load_target, seed_scatter
    from analysis.files import read_window_header
    from analysis.plume_zones import PLUME_ZONES_FILE
    from popbal.model import BOTTOM, CHANNEL, OUTER, ROOF
    from settler.cases import NO_CALIBRATION, load_case
    from settler.output import PROFILE_BANDS, band_edges

    refuse_holdouts([run], registry, "a probe")
    folder = Path(reference_dir) / run
    for name in (PLUME_ZONES_FILE, COLLISIONS_FILE):
        if not (folder / name).is_file():
            raise ValueError(f"{folder / name}: not stored; the band table needs the run's {name}")
    zones = pd.read_csv(folder / PLUME_ZONES_FILE, comment="#")
    collisions = pd.read_csv(folder / COLLISIONS_FILE, comment="#")
    start, end = read_window_header(folder / COLLISIONS_FILE)["window"]
    case_file = folder / "case.toml"
    values = {**measured_closures(registry, reference_dir, closures)["fixed"], **overrides}
    if not load_case(case_file).coalescence.enabled:
        values = {k: v for k, v in values.items() if k not in BOTTOM_KEYS}
    window = load_target(run, reference_dir, seed_scatter(reference_dir)).window
    step = (window[1] - window[0]) / 20.0
    case = load_case(case_file, {"case.calibration": NO_CALIBRATION, **values, "popbal.end_time": window[1],
                                 "popbal.output_interval": step})
    result = popbal.run(popbal.setup(case), progress=False)
    model, arrays = result.model, result.arrays
    times = np.asarray(arrays["time"])
    first = int(np.argmin(abs(times - window[0])))
    volume = (np.asarray(arrays["number_density"])[-1]
              * np.pi / 6.0 * np.nan_to_num(np.asarray(arrays["diameter"])[-1]) ** 3).sum(axis=-1)  # (Z, J)
    load = volume * np.asarray(arrays["zone_area"])[:, None]  # m^3 per m of height in each zone's cells
    held = np.asarray(arrays["number_density"])[-1].sum(axis=-1) * np.asarray(arrays["zone_area"])[:, None]  # 1/m
    merges = (np.asarray(arrays["merges"])[-1] - np.asarray(arrays["merges"])[first]) / (times[-1] - times[first])
    edges = band_edges(case.geometry.height, PROFILE_BANDS)
    height = edges[1] - edges[0]
    rows = []
    for b, (low, high) in enumerate(zip(edges[:-1], edges[1:])):
        cells = (model.z >= low) & (model.z < high)
        layer = ROOF if b == PROFILE_BANDS - 1 else BOTTOM if b == 0 else None
        rows.append({
            "z": 0.5 * (low + high),
            "full_core_load": float(zones["core_load"].iloc[b] + zones["skirt_load"].iloc[b]),
            "full_return_load": float(zones["return_load"].iloc[b]),
            "full_held": float(collisions["held"].iloc[b]),
            "full_merges_inlet": float(collisions["merges_under_inlet"].iloc[b]) / (end - start),
            "full_merges_elsewhere": float(collisions["merges_elsewhere"].iloc[b]) / (end - start),
            "popbal_channel_load": float(load[CHANNEL, cells].sum()) * model.cell_height / height,
            "popbal_outer_load": float(load[OUTER, cells].sum()) * model.cell_height / height,
            "popbal_layer_load": 0.0 if layer is None else float(load[layer].sum()) * model.cell_height / height,
            "popbal_held": float(held[[CHANNEL, OUTER]][:, cells].sum()) * model.cell_height
            + (0.0 if layer is None else float(held[layer].sum()) * model.cell_height),
            "popbal_merges_channel": float(merges[CHANNEL, cells].sum()),
            "popbal_merges_outer": float(merges[OUTER, cells].sum()),
            "popbal_merges_layer": 0.0 if layer is None else float(merges[layer].sum()),
        })
    return pd.DataFrame(rows, columns=list(BAND_COLUMNS))


def _print_bands(run, table):
    print(f"  {run}: loads [cm^3/m] full core / return | popbal channel / outer / layer;  merges [1/s] full inlet / "
          f"elsewhere | popbal channel / outer / layer;  droplets full | popbal")
    for _, r in table.iloc[::-1].iterrows():
        print(f"    z {r.z:6.3f} m  {1e6 * r.full_core_load:7.1f} / {1e6 * r.full_return_load:7.1f} | "
              f"{1e6 * r.popbal_channel_load:7.1f} / {1e6 * r.popbal_outer_load:7.1f} / {1e6 * r.popbal_layer_load:7.1f}"
              f";  {r.full_merges_inlet:7.0f} / {r.full_merges_elsewhere:6.0f} | {r.popbal_merges_channel:7.0f} / "
              f"{r.popbal_merges_outer:6.0f} / {r.popbal_merges_layer:7.0f};  {r.full_held:7.0f} | {r.popbal_held:7.0f}",
              flush=True)


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
    print("run".ljust(28) + " / ".join(c.replace("_", " ") for c in TARGET_COLUMNS) + "  [%, reduced / full - 1]")

    def report(run, errors, seconds):
        print(f"{run:28s}" + " / ".join(f"{100 * e:+5.0f}" for e in errors.values()) + f"   ({seconds:.0f} s)",
              flush=True)
        if args.bands:
            _print_bands(run, zone_bands(run, overrides, registry, args.reference_dir, args.closures))

    try:
        probe(runs, overrides, registry, args.reference_dir, args.closures, report)
    except (ValueError, CaseError) as exc:
        print(f"probe: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
