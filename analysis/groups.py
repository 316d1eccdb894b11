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
(pi mu)). ``python -m analysis.groups data/reference/design.toml`` prints the a priori table of a run set.
"""

from __future__ import annotations

import math
import sys

from settler.physics import STANDARD_GRAVITY

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
    u_s = drho * g * d * d / (18.0 * mu)
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


def measured_groups(timeseries, case) -> dict[str, float]:
    """Groups with the run's measured channel: ``channel_radius`` a and ``channel_velocity`` w0 (means over the last
    third of ``timeseries``, a DataFrame of :data:`settler.output.TIME_SERIES`): ``column_to_channel`` R / a,
    ``channel_reynolds`` rho_s w0 a / mu and ``sqrt_c`` w0 / sqrt(Q drho g / (pi mu)) [-], with the means
    ``channel_radius`` [m] and ``channel_velocity`` [m/s]."""
    late = timeseries[timeseries["time"] >= timeseries["time"].iloc[-1] * 2.0 / 3.0]
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


if __name__ == "__main__":
    print(design_table(sys.argv[1] if len(sys.argv) > 1 else "data/reference/design.toml"))
