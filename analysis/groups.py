"""The controlling groups of a settler run: what the reference set varies one at a time (data/reference/README.md).

:func:`design_groups` gives the groups a case fixes before it runs, from its inputs alone (SI units):

==========================  ==========================================================================================
``stokes_velocity``         U_s [m/s]: Stokes velocity of the mean fed droplet, (rho_m - rho_s) g d^2 / (18 mu)
``droplet_reynolds``        Re_d = rho_s U_s d / mu [-]
``feed_flux``               J [m/s]: matte volume fed per second over the inlet's area (a disk, or a slot's
                            rectangle; for a slot the plume groups below are NaN: it feeds a row of channels)
``kynch_ratio``             J / (0.0715 U_s) [-]: above 1 the feed exceeds the largest settling flux of a
                            Richardson-Zaki suspension (n = 4.65, peak at phi = 0.177), so a roof layer must build
                            up under the inlet (Kynch)
``column_radius``           R = sqrt(W D / pi) [m]: the radius of the column of the box's cross-section
``column_to_inlet``         R / a with a the inlet radius [-]: the confinement of a plume as wide as the feed
``confinement_factor``      c = A0^2 / (4 Am) of the confined Stokes plume at x = a / R, A0 = 2 ln(R/a) - 1 + x^2,
                            Am = 2 ln(R/a) - 3/2 + 2 x^2 - x^4 / 2 [-]
``plume_velocity``          w0 = sqrt(c Q drho g / (pi mu)) [m/s]: the confined Stokes plume's axis velocity for the
                            matte volume feed Q, the a priori scale of the channel velocity
``plume_reynolds``          Re_p = rho_s w0 a / mu [-]
``aspect``                  H / W [-]
==========================  ==========================================================================================

The plume law and the Kynch threshold are derived in ``shared/reference/reduced-model.md`` section 2 (the confined
Stokes plume: heavy core of radius a in a column of radius R, zero net flux, no slip at R). :func:`measured_groups`
gives the same groups from a run's measured channel (its mid-height radius and axis velocity, means over the last
third of the run): R / a and Re_p with the measured a and w0, and the measured sqrt(c) = w0 / sqrt(Q drho g /
(pi mu)). ``python -m analysis.groups data/reference/design.toml`` prints the a priori table of a run set, and
``python -m analysis.groups data/reference --measured`` the measured one of the stored runs over their steady windows
(:func:`measured_table`, with the plume's equivalent core and the floor layer; the calibration's registered
hold-outs listed without values).
"""

from __future__ import annotations

import math
import sys

from settler.physics import STANDARD_GRAVITY, stokes_velocity

#: Richardson-Zaki exponent and the peak of its settling flux phi (1 - phi)^n: 0.0715 U_s at phi = 1 / (n + 1).
RICHARDSON_ZAKI = 4.65
KYNCH_PEAK = (1.0 / (RICHARDSON_ZAKI + 1.0)) * (1.0 - 1.0 / (RICHARDSON_ZAKI + 1.0)) ** RICHARDSON_ZAKI

#: Units of the groups.
UNITS = {"stokes_velocity": "m/s", "droplet_reynolds": "-", "feed_flux": "m/s", "kynch_ratio": "-",
         "column_radius": "m", "column_to_inlet": "-", "confinement_factor": "-", "plume_velocity": "m/s",
         "plume_reynolds": "-", "aspect": "-"}


def confinement_factor(column_to_core: float) -> float:
    """c(R/a) = A0^2 / (4 Am) of the confined Stokes plume (module docstring) [-]; NaN for R/a <= 1. The one
    definition is popbal's closure (:func:`popbal.closures.confined_plume_coefficient`), which the reduced model
    applies under ``popbal.confinement``."""
    from popbal.closures import confined_plume_coefficient

    return confined_plume_coefficient(column_to_core)


def design_groups(case) -> dict[str, float]:
    """The a priori groups of ``case`` (a :class:`settler.cases.Case`; module docstring)."""
    g = STANDARD_GRAVITY
    mu, rho_s, rho_m = case.slag_viscosity, case.slag.density, case.matte.density
    d = case.feed.mean_diameter
    drho = rho_m - rho_s
    u_s = stokes_velocity(d, rho_m, rho_s, mu, g)
    a = 0.5 * case.geometry.inlet_diameter
    q = case.feed.mass_rate / rho_m
    from popbal.model import column_radius

    radius = column_radius(case)
    if case.inlet_is_slot:  # a row of channels: the single axisymmetric plume's laws do not apply
        flux = q / case.inlet_area
        return {"stokes_velocity": u_s, "droplet_reynolds": rho_s * u_s * d / mu, "feed_flux": flux,
                "kynch_ratio": flux / (KYNCH_PEAK * u_s), "column_radius": radius, "column_to_inlet": math.nan,
                "confinement_factor": math.nan, "plume_velocity": math.nan, "plume_reynolds": math.nan,
                "aspect": case.geometry.height / case.geometry.width}
    flux = q / (math.pi * a * a) if a > 0.0 else math.nan
    c = confinement_factor(radius / a) if a > 0.0 else math.nan
    w0 = math.sqrt(c * q * drho * g / (math.pi * mu)) if q > 0.0 else 0.0
    return {"stokes_velocity": u_s, "droplet_reynolds": rho_s * u_s * d / mu, "feed_flux": flux,
            "kynch_ratio": flux / (KYNCH_PEAK * u_s), "column_radius": radius,
            "column_to_inlet": radius / a if a > 0.0 else math.nan, "confinement_factor": c, "plume_velocity": w0,
            "plume_reynolds": rho_s * w0 * a / mu, "aspect": case.geometry.height / case.geometry.width}


def measured_groups(timeseries, case, window: tuple[float, float] | None = None) -> dict[str, float]:
    """Groups with the run's measured channel: ``channel_radius`` a and ``channel_velocity`` w0 (means over
    ``window`` [s], default the last third of ``timeseries``, a DataFrame of :data:`settler.output.TIME_SERIES`):
    ``column_to_channel`` R / a, ``channel_reynolds`` rho_s w0 a / mu and ``sqrt_c`` w0 / sqrt(Q drho g / (pi mu))
    [-], with the means ``channel_radius`` [m] and ``channel_velocity`` [m/s]."""
    start, end = window if window is not None else (timeseries["time"].iloc[-1] * 2.0 / 3.0, math.inf)
    late = timeseries[(timeseries["time"] >= start) & (timeseries["time"] <= end)]
    a = float(late["channel_radius"].mean())
    w0 = float(late["channel_velocity"].mean())
    mu, rho_s, rho_m = case.slag_viscosity, case.slag.density, case.matte.density
    q = case.feed.mass_rate / rho_m
    from popbal.model import column_radius

    radius = column_radius(case)
    scale = math.sqrt(q * (rho_m - rho_s) * STANDARD_GRAVITY / (math.pi * mu)) if q > 0.0 else math.nan
    return {"channel_radius": a, "channel_velocity": w0, "column_to_channel": radius / a if a > 0 else math.nan,
            "channel_reynolds": rho_s * w0 * a / mu, "sqrt_c": w0 / scale if scale > 0 else math.nan}


def design_table(path) -> str:
    """A Markdown table of the a priori groups of every run of a run-set file."""
    from analysis.sweep.runset import load_run_set

    columns = [("Re_d", "droplet_reynolds", ".2g"), ("J/(0.0715 U_s)", "kynch_ratio", ".3g"),
               ("R/a", "column_to_inlet", ".3g"), ("c", "confinement_factor", ".2f"),
               ("w0 [mm/s]", "plume_velocity", ".3g"), ("Re_p", "plume_reynolds", ".2g"), ("H/W", "aspect", ".3g")]
    lines = ["| run | family | case and overrides | " + " | ".join(c[0] for c in columns) + " |",
             "|" + "---|" * (3 + len(columns))]
    for run in load_run_set(path).runs:
        groups = design_groups(run.case)
        changes = ", ".join(f"{k}={v}" for k, v in run.overrides.items()) or "-"
        cells = ["-" if math.isnan(groups[key]) else format(groups[key] * (1e3 if key == "plume_velocity" else 1.0),
                                                            spec) for _, key, spec in columns]
        lines.append(f"| {run.name} | {run.family} | {run.case.case.name}: {changes} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


#: The measured table's columns: (heading, key, format, scale to the heading's unit).
MEASURED_COLUMNS = (("window [s]", "window", "", 1.0), ("a [mm]", "channel_radius", ".3g", 1e3),
                    ("w0 [mm/s]", "channel_velocity", ".3g", 1e3), ("R/a", "column_to_channel", ".3g", 1.0),
                    ("Re_p", "channel_reynolds", ".2g", 1.0), ("sqrt(c)", "sqrt_c", ".2f", 1.0),
                    ("w0/u_K", "stokes_ratio", ".2f", 1.0), ("A0*", "core_a0", ".2f", 1.0),
                    ("R* [mm]", "core_radius", ".3g", 1e3), ("t", "plume_speed_ratio", ".2f", 1.0),
                    ("R*_t [mm]", "moving_core_radius", ".3g", 1e3), ("delta_b [mm]", "floor_thickness", ".3g", 1e3),
                    ("delta_b/a", "floor_to_channel", ".2f", 1.0))


def stored_measured_groups(folder) -> dict:
    """The measured groups of a stored reference run (``data/reference/<name>/``) over its steady window (else its
    last third; :func:`analysis.steady.window_of`): :func:`measured_groups`, and where the run keeps them
    ``stokes_ratio`` w0 / u_K (the axis velocity over the confined Stokes flow its droplets drive, middle bands,
    ``plume_force.csv``; :mod:`analysis.plume_force`) with ``core_a0`` A0* = W w0 / Q [-] and ``core_radius`` R* [m]
    (the uniform core carrying the feed at the axis speed that drives the run's axis at that ratio;
    :func:`analysis.plume_force.equivalent_core`), and with ``plume_zones.csv`` ``plume_speed_ratio`` t [-] (the plume
    droplets' speed over the axis speed, :func:`analysis.plume_zones.plume_speed_ratio`) and ``moving_core_radius``
    R*_t [m] (the same core carrying the feed at t u), ``floor_thickness`` delta_b [m] (the excess thickness of the
    matte layer over the floor, ``floor_layer.csv``; :mod:`analysis.floor_layer`) and ``floor_to_channel`` delta_b / a
    [-]; ``window`` (start, end) [s] and ``steady``."""
    from pathlib import Path

    from analysis.floor_layer import read_floor_layer
    from analysis.plume_force import equivalent_core, middle_ratio, read_plume_force
    from analysis.runs import load_run
    from analysis.steady import window_of
    from settler.cases import load_case

    folder = Path(folder)
    run = load_run(folder)
    window, steady = window_of(run.timeseries)
    case = load_case(folder / "case.toml")
    out: dict = {"window": window, "steady": steady}
    if case.inlet_is_slot or case.feed.mass_rate <= 0.0:  # no single plume: its groups mean nothing
        return out
    out.update(measured_groups(run.timeseries, case, window))
    if (folder / "plume_force.csv").is_file():
        from popbal.model import column_radius

        table = read_plume_force(folder / "plume_force.csv")[0]
        out["stokes_ratio"] = middle_ratio(table)
        plume = (table, case.feed.mass_rate / case.matte.density, column_radius(case), case.slag_viscosity,
                 case.matte.density - case.slag.density)
        core = equivalent_core(*plume)
        out["core_a0"], out["core_radius"] = core["a0"], core["core_radius"]
        if (folder / "plume_zones.csv").is_file():
            from analysis.plume_zones import plume_speed_ratio, read_plume_zones

            out["plume_speed_ratio"] = speed = plume_speed_ratio(read_plume_zones(folder / "plume_zones.csv")[0])
            if speed > 0.0:
                out["moving_core_radius"] = equivalent_core(*plume, speed)["core_radius"]
    if (folder / "floor_layer.csv").is_file():
        out["floor_thickness"] = read_floor_layer(folder / "floor_layer.csv")[1]["thickness"]
        out["floor_to_channel"] = out["floor_thickness"] / out["channel_radius"]
    return out


def measured_table(reference_dir, holdouts=None) -> str:
    """A Markdown table of :func:`stored_measured_groups` for every stored run of ``reference_dir``; the runs named
    in ``holdouts`` (the calibration's pre-registered hold-outs) are listed without their values, which no closure
    may be chosen from."""
    from pathlib import Path

    held = set(holdouts or ())
    lines = ["| run | " + " | ".join(c[0] for c in MEASURED_COLUMNS) + " |", "|" + "---|" * (1 + len(MEASURED_COLUMNS))]
    for folder in sorted(p.parent for p in Path(reference_dir).glob("*/reference.json")):
        if folder.name in held:
            lines.append(f"| {folder.name} | held out (data/calibration/holdouts.toml): not shown |"
                         + " |" * (len(MEASURED_COLUMNS) - 1))
            continue
        groups = stored_measured_groups(folder)
        start, end = groups["window"]
        cells = [f"{start:.3g}-{end:.3g}" + ("" if groups["steady"] else " (last third)")]
        for _, key, spec, scale in MEASURED_COLUMNS[1:]:
            value = groups.get(key, math.nan)
            cells.append("-" if not math.isfinite(value) else format(value * scale, spec))
        lines.append(f"| {folder.name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    import argparse
    from pathlib import Path

    parser = argparse.ArgumentParser(prog="python -m analysis.groups", description=(
        "print the controlling groups of a run set as a Markdown table: a priori from a run-set file (the default, "
        "data/reference/design.toml), or measured from a folder of stored reference runs with --measured"))
    parser.add_argument("source", nargs="?", default="data/reference/design.toml",
                        help="a run-set file (default data/reference/design.toml), or with --measured a folder of "
                             "stored runs (data/reference)")
    parser.add_argument("--measured", action="store_true",
                        help="the groups measured over each stored run's steady window (the registered hold-outs "
                             "of --registry listed without their values)")
    parser.add_argument("--registry", default="data/calibration/holdouts.toml",
                        help="the calibration's registry whose hold-outs --measured leaves out (default "
                             "data/calibration/holdouts.toml; 'none' for none)")
    args = parser.parse_args(argv)
    source = Path(args.source)
    if args.measured:
        if not source.is_dir():
            print(f"analysis.groups: --measured {args.source}: allowed: a folder of stored reference runs "
                  "(data/reference)", file=sys.stderr)
            return 2
        holdouts = ()
        if args.registry != "none":
            from analysis.calibration.registry import RegistryError, load_registry

            try:
                holdouts = load_registry(args.registry).holdouts
            except (OSError, RegistryError) as err:
                print(f"analysis.groups: --registry {args.registry}: {err}", file=sys.stderr)
                return 2
        print(measured_table(source, holdouts))
        return 0
    if not source.is_file():
        print(f"analysis.groups: {args.source}: allowed: a run-set file (data/reference/design.toml)", file=sys.stderr)
        return 2
    print(design_table(source))
    return 0


if __name__ == "__main__":
    sys.exit(main())
