"""The closures the hierarchical calibration measures in the reference runs' zone diagnostics rather than fits
(SI units): the plume's radius factor and dilution law (``zone_profile.csv``, ``channel_profile.csv``), the roof
layer's law, its drainage law and its kernel (``zones.csv``, ``collisions_by_height.csv``) and the channel's kernel,
each from named stored runs and never from a hold-out (:mod:`analysis.calibration.hierarchy` passes the runs).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.files import MeasureError

#: Largest cell size [m] at which a run's roof layer counts for the drainage law's k: the zone diagnostics count the
#: roof in slices one cell high, and at 5 mm cells every roof is one or two cells thick (its volume fraction the
#: cell's: j / (phi_L U_s) 2.8-9.4 against 2.3-2.8 at 3.3 and 2.5 mm cells, docs/guide/reduced-model.md). [chosen]
ROOF_RESOLVED_CELL = 3.4e-3
#: Height band [-, of the column height] over which the core volume fraction is averaged for k_R.
CORE_BAND = (0.3, 0.7)


def _geometric_mean(values) -> float:
    """exp(mean(ln x)) of the positive ``values`` [their unit]: how every per-run measure here is pooled."""
    return float(np.exp(np.mean(np.log(list(values)))))


def _geometric_mean_with_error(values) -> tuple[float, float]:
    """(geometric mean, its standard error b x se(mean ln b), NaN from one value) of the positive ``values``."""
    logs = np.log(list(values))
    value = float(np.exp(logs.mean()))
    return value, value * float(np.std(logs, ddof=1) / math.sqrt(len(logs))) if len(logs) > 1 else math.nan


def _core_band(folder: Path, table: str) -> pd.DataFrame:
    """The rows of a stored run's ``table`` (zone_profile.csv or channel_profile.csv) in the :data:`CORE_BAND` of the
    height over the run's steady window."""
    from analysis.runs import load_run

    from .targets import window_of

    profile = pd.read_csv(folder / table, comment="#")
    (start, end), _ = window_of(load_run(folder).timeseries)
    height = float(profile["z"].max() + profile["z"].min())  # cell centres: first + last = the height
    return profile[(profile["time"] > start) & (profile["z"] >= CORE_BAND[0] * height)
                   & (profile["z"] <= CORE_BAND[1] * height)]


def radius_factor_from_zones(runs, reference_dir: str | Path) -> dict:
    """k_R = phi_p^(-1/2) [-] from the plume core's volume fraction phi_p (``zone_profile.csv``: the mean of
    core_volume_fraction over the :data:`CORE_BAND` of the height and the runs' steady windows)."""
    fractions = [float(_core_band(Path(reference_dir) / run, "zone_profile.csv")["core_volume_fraction"].mean())
                 for run in runs]
    phi = float(np.mean(fractions))
    return {"value": phi ** -0.5, "core_fraction": phi, "runs": list(runs)}


def dilution_from_zones(runs, reference_dir: str | Path) -> dict:
    """The plume's dilution law phi_p = k_R^-2 / (1 + Re / Re_d) (popbal.closures, ``plume_dilution_reynolds``)
    from the zone diagnostics of ``runs``: per run the core volume fraction phi_p (as :func:`radius_factor_from_zones`)
    and the slag's axis velocity u (``channel_profile.csv``, the same band and window), the radius R = sqrt(Q_ch /
    (pi phi_p u)) that carries the feed at them and Re = rho_s u R / mu; k_R and Re_d by least squares in log phi_p,
    with standard errors and their correlation from the residuals' scatter. A run whose R exceeds its inlet radius is
    left out (``excluded``): its plume fills the feed's disk, which popbal caps, and measures the cap, not the law.
    Returns {"value": k_R, "core_fraction": k_R^-2, "reynolds": Re_d, "standard_errors": {...}, "correlation",
    "rms" (of the log residuals), "per_run": {run: (phi_p, Re)}, "excluded": {run: why}, "runs"}."""
    from popbal.closures import plume_reynolds
    from popbal.model import channel_volume_flux
    from settler.cases import load_case

    per_run, excluded = {}, {}
    for run in runs:
        folder = Path(reference_dir) / run
        phi = float(_core_band(folder, "zone_profile.csv")["core_volume_fraction"].mean())
        u = float(_core_band(folder, "channel_profile.csv")["channel_velocity"].mean())
        case = load_case(folder / "case.toml")
        flux = channel_volume_flux(case)
        radius = math.sqrt(flux / (math.pi * phi * u))
        if radius > 0.5 * case.geometry.inlet_diameter:
            excluded[run] = (f"R {radius * 1e3:.3g} mm over the inlet radius "
                             f"{case.geometry.inlet_diameter * 500:.3g} mm")
            continue
        per_run[run] = (phi, plume_reynolds(u, radius, case.slag.density, case.slag_viscosity))
    if len(per_run) < 3:
        raise MeasureError(f"the dilution law needs the zones of at least 3 runs whose plume is narrower than the "
                           f"inlet; got {', '.join(per_run) or 'none'} (left out: {excluded or 'none'})")
    phi, reynolds = (np.array(v) for v in zip(*per_run.values()))
    return {**fit_dilution(phi, reynolds), "per_run": {r: (float(a), float(b)) for r, (a, b) in per_run.items()},
            "excluded": excluded, "runs": list(per_run)}


def fit_dilution(phi, reynolds) -> dict:
    """k_R and Re_d of phi = k_R^-2 / (1 + Re / Re_d) from volume fractions ``phi`` and Reynolds numbers
    ``reynolds`` (arrays, n >= 3) by least squares in log phi; standard errors (``standard_errors``, by [popbal]
    key) and their ``correlation`` from the residuals' scatter, ``rms`` of the log residuals."""
    from scipy.optimize import least_squares

    phi, reynolds = np.asarray(phi, dtype=float), np.asarray(reynolds, dtype=float)
    fit = least_squares(lambda x: x[0] - np.log1p(reynolds / np.exp(x[1])) - np.log(phi),
                        [math.log(float(phi.max())), 0.0], xtol=1e-14, ftol=1e-14, gtol=1e-14)
    dof = len(phi) - 2
    covariance = np.linalg.pinv(fit.jac.T @ fit.jac) * (2.0 * fit.cost / dof if dof > 0 else math.nan)
    se = np.sqrt(np.diag(covariance))
    phi0, re_d = math.exp(fit.x[0]), math.exp(fit.x[1])
    with np.errstate(invalid="ignore", divide="ignore"):  # runs of one Reynolds number: no correlation to give
        correlation = float(covariance[0, 1] / (se[0] * se[1]))
    return {"value": phi0 ** -0.5, "core_fraction": phi0, "reynolds": re_d,
            # relative errors of phi0 and Re_d are the log parameters' standard errors; k_R's is half phi0's
            "standard_errors": {"channel_radius_factor": 0.5 * se[0] * phi0 ** -0.5,
                                "plume_dilution_reynolds": se[1] * re_d},
            "correlation": correlation, "rms": float(np.sqrt(np.mean(fit.fun ** 2)))}


def _roof_layer(folder: Path, start: float, end: float) -> tuple[float, float]:
    """(mean roof thickness delta [m], matte per unit area I = mean(thickness x volume fraction) [m]) of the roof
    layer in a stored run's ``zones.csv`` over ``start``-``end`` [s]."""
    zones = pd.read_csv(Path(folder) / "zones.csv", comment="#")
    rows = zones[(zones["time"] >= start) & (zones["time"] <= end)]
    return (float(rows["roof_thickness"].mean()),
            float((rows["roof_thickness"] * rows["roof_volume_fraction"].fillna(0.0)).mean()))


def roof_from_zones(runs, reference_dir: str | Path) -> dict:
    """The roof law's c_L [-] and thickness delta [m] from the roof layer of the zone diagnostics (``zones.csv``):
    per run, over its steady window, the matte volume per unit area I = mean(roof_thickness x roof_volume_fraction)
    and c_L = (j - w I / delta) mu / (drho g I^2) (popbal.closures.roof_coefficient, j the matte feed over the inlet
    disk, w the slag feed's velocity through it, delta the run's mean roof thickness); c_L the geometric mean over
    the runs, delta the mean thickness. The drainage law's k = j delta / (I U_s) (the layer's drainage velocity over
    the Stokes velocity U_s of the mean fed droplet, :func:`popbal.closures.roof_drainage_thickness`): the geometric
    mean over the runs whose cells resolve the roof (at most :data:`ROOF_RESOLVED_CELL`; per run in
    "drainage_per_run"), NaN where none does."""
    from analysis.runs import load_run
    from popbal.closures import roof_coefficient
    from popbal.model import roof_slag_velocity
    from settler.cases import load_case

    from .targets import window_of

    from analysis.groups import design_groups

    per_run, thickness, drainage = {}, [], {}
    for run in runs:
        folder = Path(reference_dir) / run
        (start, end), _ = window_of(load_run(folder).timeseries)
        mean_thickness, inventory = _roof_layer(folder, start, end)
        case = load_case(folder / "case.toml")
        inlet = math.pi * (0.5 * case.geometry.inlet_diameter) ** 2
        flux = case.feed.mass_rate / case.matte.density / inlet
        if case.fulldem.cell_size <= ROOF_RESOLVED_CELL and inventory > 0.0:
            drainage[run] = flux * mean_thickness / (inventory * design_groups(case)["stokes_velocity"])
        slag = roof_slag_velocity(case, roof=True, horizontal=case.popbal.slag_flow == "horizontal")
        thickness.append(mean_thickness)
        per_run[run] = roof_coefficient(flux, inventory, case.matte.density - case.slag.density, case.slag_viscosity,
                                        slag_velocity=slag, thickness=thickness[-1])
        if not per_run[run] > 0.0:
            raise ValueError(f"{folder}: its roof layer (matte {inventory:.3g} m per unit area, {thickness[-1]:.3g} m "
                             f"thick) is carried by the slag feed alone ({slag:.3g} m/s through the inlet against "
                             f"the matte's {flux:.3g} m/s): no cloud drainage to measure c_L from; leave the run out "
                             "of the level or use a closure set without a roof layer")
    coefficient = _geometric_mean(per_run.values())
    return {"coefficient": coefficient, "thickness": float(np.mean(thickness)), "per_run": per_run, "runs": list(runs),
            "drainage_ratio": _geometric_mean(drainage.values()) if drainage else math.nan,
            "drainage_per_run": drainage}


def _collisions_with_shear(folder: Path, needs: str):
    """(table, meta) of a stored run's collisions by height (:func:`analysis.band_efficiency.read_collisions`) with
    its well-mixed shear columns; FileNotFoundError naming the file and what ``needs`` it where either is missing."""
    from analysis.band_efficiency import COLLISIONS_FILE, read_collisions

    path = folder / COLLISIONS_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{folder}: no {COLLISIONS_FILE} (stored runs measure it when made with "
                                f"merges_by_height.csv, a04ea13 or later); {needs} needs it")
    table, meta = read_collisions(path)
    if "mixed_shear_under_inlet" not in table:
        raise FileNotFoundError(f"{path}: no well-mixed shear collisions (stored before 2026-12-05); store the "
                                "run again from its run folder (python -m analysis.reference_set)")
    return table, meta


def law_roof_thickness(case_file, fixed: dict) -> float:
    """popbal's roof thickness [m] in the case of ``case_file`` under the [popbal] overrides ``fixed`` (its own
    calibration layer set aside, as the fit scores it): :func:`popbal.model.roof_thickness`."""
    from popbal.model import roof_thickness
    from settler.cases import NO_CALIBRATION, load_case

    keys = {k: v for k, v in fixed.items() if k.startswith("popbal.roof_")}
    return roof_thickness(load_case(case_file, {"case.calibration": NO_CALIBRATION, **keys}))


def roof_kernel_from_collisions(runs, reference_dir: str | Path, thickness: float | dict | None = None,
                                hindered_exponent: float | None = None) -> dict:
    """The roof layer's own kernel [-] as popbal's roof applies it, from each full run's zone diagnostics over the
    window of its collisions by height (``collisions_by_height.csv``, measured over the steady window when the run
    was stored; :mod:`analysis.band_efficiency`), in the top band under the inlet (the disk of area A):

    - the layer, as popbal's: matte per unit area I, the mean of ``zones.csv``'s roof_thickness x
      roof_volume_fraction over the window (as :func:`roof_from_zones`), so that the layer holds the share
      f = I A / V_b of the band's matte V_b (at most 1; the rest is plume below it), over popbal's thickness delta
      (``thickness`` [m], the one popbal's roof will have: the calibration passes the layers' delta, or {run:
      delta} where popbal's roof thickness is a law; None: each run's own mean roof_thickness), so that popbal's roof
      holding the run's I collides and drains as the run's;
    - efficiency E_L = merges / C_L, with C_L = (C_g + C_s) f^2 h_b / delta the band's well-mixed gravitational and
      shear collisions (the latter at the slag's shear rate at its droplets) carried over to the layer's droplets mixed
      over its own volume A delta (a pair sum scales as the droplets squared, at the band's size distribution) from
      the band's A h_b (h_b the band's height): popbal's roof collides its droplets mixed over A delta;
    - shear coefficient G delta / u_L, G the slag's shear rate at the band's droplets and u_L = j delta / I - w the
      layer's own drainage velocity from its balance j = (I / delta) (u_L + w) (j the matte fed over the inlet, w the
      slag feed's velocity through it; popbal.closures): popbal shears its roof at G = roof_shear_coefficient u_L /
      delta.

    With ``hindered_exponent`` n the gravitational collisions are counted as popbal's roof counts them: the table's
    are at the droplets' terminal velocities (:mod:`analysis.band_efficiency`), popbal's kernel takes their hindered
    ones, so C_g is multiplied by (1 - phi_L)^n at the layer's volume fraction phi_L = I / delta (per run in
    "hindrance"); without it (None) E_L holds against terminal velocities, and popbal's roof, which holds phi_L,
    merges (1 - phi_L)^n of what the run's top band does (0.765 in simple at zones_core's values).

    Each the geometric mean over the runs; per run in "per_run". A run without the table, without the well-mixed
    shear columns, without merges or shear in its top band, or whose roof the slag alone would carry is refused by
    name, and so is an empty list of runs."""
    from analysis.band_efficiency import COLLISIONS_FILE
    from popbal.model import roof_slag_velocity
    from settler.cases import load_case
    from settler.physics import richardson_zaki_factor

    if not runs:
        raise MeasureError("the roof kernel needs at least one run with coalescence and a roof among the whole level's "
                           "stored runs; none is stored")
    per_run = {}
    for run in runs:
        folder = Path(reference_dir) / run
        path = folder / COLLISIONS_FILE
        table, meta = _collisions_with_shear(folder, "the roof kernel")
        top = table.iloc[int(np.argmax(table["z"].to_numpy()))]
        if not math.isfinite(top["mixed_shear_under_inlet"]) or not math.isfinite(top["shear_rate_under_inlet"]):
            raise ValueError(f"{path}: no slag shear rate in the top band under the inlet (measured without the whole "
                             "slag grid); the roof kernel needs it")
        if not (top["merges_under_inlet"] > 0 and top["mixed_under_inlet"] + top["mixed_shear_under_inlet"] > 0):
            raise ValueError(f"{path}: no merges or no collisions in the top band under the inlet; the roof kernel "
                             "needs runs with coalescence and a roof")
        case = load_case(folder / "case.toml")
        own, inventory = _roof_layer(folder, *meta["window"])
        delta = own if thickness is None else float(thickness[run] if isinstance(thickness, dict) else thickness)
        area = math.pi * (0.5 * case.geometry.inlet_diameter) ** 2
        band = case.geometry.height / len(table)
        share = min(inventory * area / float(top["volume_under_inlet"]), 1.0)
        hindrance = 1.0 if hindered_exponent is None else richardson_zaki_factor(min(inventory / delta, 1.0),
                                                                                 hindered_exponent)
        collisions = float(hindrance * top["mixed_under_inlet"] + top["mixed_shear_under_inlet"]) * share**2 \
            * band / delta
        flux = case.feed.mass_rate / case.matte.density / area
        slag = roof_slag_velocity(case, roof=True, horizontal=case.popbal.slag_flow == "horizontal")
        drainage = flux * delta / inventory - slag
        if not drainage > 0.0:
            raise ValueError(f"{folder}: its roof layer (matte {inventory:.3g} m per unit area, {delta:.3g} m "
                             f"thick) is carried by the slag feed alone; no drainage velocity to scale its shear by")
        rate = float(top["shear_rate_under_inlet"])
        per_run[run] = {"efficiency": float(top["merges_under_inlet"]) / collisions,
                        "shear_coefficient": rate * delta / drainage, "shear_rate": rate, "thickness": own,
                        "share": share, "drainage_velocity": drainage, "hindrance": hindrance}

    def mean(key):
        return _geometric_mean(v[key] for v in per_run.values())

    return {"efficiency": mean("efficiency"), "shear_coefficient": mean("shear_coefficient"), "per_run": per_run,
            "runs": list(runs), "thickness": thickness, "hindered_exponent": hindered_exponent}


def channel_kernel_from_collisions(runs, reference_dir: str | Path, values: dict | None = None) -> dict:
    """The plume channel's own kernel [-] as popbal's channel would apply it, from each full run's zone diagnostics
    (``collisions_by_height.csv``, over the steady window it was stored with; :mod:`analysis.band_efficiency`) in the
    bands between the top one (the roof's) and the bottom one (the floor's, popbal's bottom layer), under the inlet
    (its disk or slot extended down, area A_in):

    - popbal's channel at the [popbal] ``values`` (dotted keys, e.g. {"popbal.channel_radius_factor": 4.94}, on
      each run's own case.toml, with its calibration layer set aside): its radius R_c, plume velocity u_s and
      transport factor t (:func:`popbal.model.channel_closure`);
    - efficiency E_ch = merges / C_ch, C_ch = (C_g + C_s) A_in / (pi R_c^2): the bands' gravitational and shear
      collisions of the droplets well mixed under the inlet (the shear at the slag's own rate at them) carried over
      to the droplets mixed over the channel's section, as popbal's channel holds them (a pair sum scales as the
      inverse of the volume);
    - shear coefficient G R_c / (t u_s), G the slag's shear rate at the bands' droplets (mean over the bands weighted
      by the droplets held): popbal shears its channel at G = shear_coefficient t u_s / R_c;
    - collision radius sqrt(A_in / pi) sqrt(C_g,mixed / C_g,cell) [m]: the radius of the disk over which the bands'
      droplets, well mixed, would collide as often as they do cell by cell (how compact the plume keeps them), and
      the cell-by-cell efficiency merges / C_g,cell.

    E_ch and the shear coefficient as geometric means over the runs; per run in "per_run". A run without the table,
    its well-mixed shear columns or merges between the top and bottom bands is refused by name, as is an empty list
    of runs."""
    from analysis.band_efficiency import COLLISIONS_FILE
    from fulldem.boundaries import Inlet
    from popbal.model import channel_closure
    from settler.cases import NO_CALIBRATION, load_case

    if not runs:
        raise MeasureError("the channel kernel needs at least one stored run with coalescence; none was given")
    per_run = {}
    for run in runs:
        folder = Path(reference_dir) / run
        path = folder / COLLISIONS_FILE
        table, _ = _collisions_with_shear(folder, "the channel kernel")
        below = table.sort_values("z").iloc[1:-1]
        merges = float(below["merges_under_inlet"].sum())
        mixed = float(below["mixed_under_inlet"].sum())
        mixed_shear = float(below["mixed_shear_under_inlet"].sum())
        cell = float(below["gravitational_under_inlet"].sum())
        if not (merges > 0.0 and mixed > 0.0 and cell > 0.0 and math.isfinite(mixed_shear)):
            raise ValueError(f"{path}: no merges, collisions or shear rate under the inlet between the top and "
                             "bottom bands; the channel kernel needs a run with coalescence measured on its whole "
                             "slag grid")
        case = load_case(folder / "case.toml", {"case.calibration": NO_CALIBRATION, **(values or {})})
        g = case.geometry
        radius, velocity, _, transport = channel_closure(case)
        inlet = Inlet(tuple(case.inlet_center), 0.5 * g.inlet_diameter, g.height, g.inlet_length or 0.0).area
        collisions = (mixed + mixed_shear) * inlet / (math.pi * radius**2)
        held = below["held"].to_numpy()
        rate = float(np.average(below["shear_rate_under_inlet"].to_numpy(), weights=held))
        per_run[run] = {"efficiency": merges / collisions, "shear_coefficient": rate * radius / (transport * velocity),
                        "shear_rate": rate, "channel_radius": radius, "plume_velocity": velocity,
                        "collision_radius": math.sqrt(inlet / math.pi * mixed / cell),
                        "cell_efficiency": merges / cell}

    def mean(key):
        return _geometric_mean(v[key] for v in per_run.values())

    return {"efficiency": mean("efficiency"), "shear_coefficient": mean("shear_coefficient"), "per_run": per_run,
            "runs": list(runs)}


def floor_shear_from_collisions(runs, reference_dir: str | Path, values: dict | None = None) -> dict:
    """The bottom layer's shear coefficient c_b [-] as popbal's bottom layer applies it (G = c_b u_s t / h_b,
    ``popbal.bottom_shear_coefficient``), from each full run's zone diagnostics (``collisions_by_height.csv``, over
    the steady window it was stored with; :mod:`analysis.band_efficiency`) in the bottom band (the floor's):

    - the full run's G: the slag's shear rate at the band's droplets under the inlet and elsewhere, weighted by the
      droplet volume each holds (popbal's layer spans the whole floor);
    - popbal's G at c_b = 1 in the run's case at the [popbal] ``values`` (dotted keys, its calibration layer set
      aside; they must give it a bottom layer): u_s t / h_b, the plume's droplet velocity over the layer's thickness
      (:func:`popbal.model.build`);
    - c_b = their ratio.

    c_b the geometric mean over the runs; per run in "per_run" (shear_rate, popbal_shear_rate, coefficient). A run
    without the table, a shear rate in its bottom band or a bottom layer at ``values`` is refused by name, as is an
    empty list of runs."""
    import popbal
    from analysis.band_efficiency import COLLISIONS_FILE
    from settler.cases import NO_CALIBRATION, load_case

    if not runs:
        raise MeasureError("the bottom layer's shear needs at least one stored run with its collisions by height; none "
                           "was given")
    per_run = {}
    for run in runs:
        folder = Path(reference_dir) / run
        path = folder / COLLISIONS_FILE
        table, _ = _collisions_with_shear(folder, "the bottom layer's shear")
        floor = table.iloc[int(np.argmin(table["z"].to_numpy()))]
        rates = np.array([floor["shear_rate_under_inlet"], floor["shear_rate_elsewhere"]], dtype=float)
        held = np.array([floor["volume_under_inlet"], floor["volume_elsewhere"]], dtype=float)
        known = np.isfinite(rates) & (held > 0.0)
        if not known.any():
            raise ValueError(f"{path}: no slag shear rate at droplets in the bottom band; the bottom layer's shear "
                             "needs it")
        rate = float(np.average(rates[known], weights=held[known]))
        case = load_case(folder / "case.toml", {"case.calibration": NO_CALIBRATION, **(values or {})})
        model = popbal.setup(case)
        if not model.bottom:
            raise ValueError(f"{folder}: popbal has no bottom layer in this case at the values given (set "
                             "popbal.bottom_layer_factor); the bottom layer's shear is measured against it")
        own = model.bottom_turning_rate
        per_run[run] = {"shear_rate": rate, "popbal_shear_rate": own, "coefficient": rate / own}
    value = _geometric_mean(v["coefficient"] for v in per_run.values())
    return {"value": value, "per_run": per_run, "runs": list(runs)}


def spread_share_from_groups(runs, reference_dir: str | Path, fixed: dict) -> dict:
    """The spread plume's slag core over the column, s = R* / R [-] (R* the equivalent core at the axis speed,
    :func:`analysis.groups.stored_measured_groups`; R the column's equivalent radius): the geometric mean over the
    ``runs`` that popbal's regime rule spreads under ``fixed`` ({dotted key: value}, with popbal.plume_core_radius
    R_0: the feed Reynolds number rho_s Q / (mu L) reaching popbal.spread_flux_reynolds, L =
    popbal.spread_reference_radius or R_0), with its standard error; ValueError where none does."""
    from analysis.groups import stored_measured_groups
    from popbal.model import column_radius, plume_spreads
    from settler.cases import load_case

    shares = {}
    for run in runs:
        folder = Path(reference_dir) / run
        case = load_case(folder / "case.toml", {k: v for k, v in fixed.items() if k.startswith("popbal.")})
        if plume_spreads(case):  # popbal's own rule
            shares[run] = stored_measured_groups(folder)["core_radius"] / column_radius(case)
    if not shares:
        raise MeasureError(f"no run of {', '.join(runs) or 'none'} is spread by the regime rule: the spread core's "
                           "share cannot be measured")
    value, se = _geometric_mean_with_error(shares.values())
    return {"value": value, "standard_error": se, "per_run": shares, "runs": list(shares)}


def _with_snapshots(runs, reference_dir) -> tuple[list[str], list[str]]:
    """(the ``runs`` that store a droplet snapshot, those that store none): the measures of droplets' positions take
    the former and name the latter."""
    from analysis.runs import load_run

    have = [r for r in runs if len(load_run(Path(reference_dir) / r).snapshot_times())]
    return have, [r for r in runs if r not in have]


def collision_radius_from_clustering(runs, reference_dir: str | Path, fixed: dict) -> dict:
    """The plume channel's collision radius b [m] per regime (popbal.channel_collision_radius and
    spread_channel_collision_radius): per run :mod:`analysis.channel_clustering`'s interior collision radius over the
    grid columns within popbal's channel radius R_c under ``fixed`` ({dotted key: value}, on the run's own case.toml
    with its calibration layer set aside; :func:`popbal.model.channel_closure`), the runs split by popbal's regime
    rule (:func:`popbal.model.plume_spreads`) and each regime's geometric mean with its standard error (the mean log's
    carried to b, b x se(ln b); NaN from one run). A run whose droplets collide no more often cell by cell than
    mixed over the disk (S <= 1, or no pair: NaN) is "excluded", not pooled: popbal's law E_ch = E max(1, (R_c /
    b)^2) cannot carry S < 1 (deep_w002's 5 mm channel, 12 columns, gives S 0.07); "with_excluded" is the compact
    regime's pool with those whose b is finite, for comparison. Returns {"compact": {"value", "standard_error",
    "runs"}, "spread": the same or None, "with_excluded": the same or None, "per_run": {run: {"regime",
    "collision_radius", "clustering", "channel_radius", "equivalent_radius"}}, "no_snapshot": [runs that store no
    droplet snapshot, left out], "excluded": [runs]}. ValueError where no compact run is pooled, or a run spreads
    and no spread run is pooled (the compact b would then stand for a plume it was not measured in)."""
    from analysis.channel_clustering import interior, measure_clustering
    from popbal.model import channel_closure, plume_spreads
    from settler.cases import NO_CALIBRATION, load_case

    per_run, regimes = {}, {}
    measurable, unmeasured = _with_snapshots(runs, reference_dir)
    for run in runs:
        folder = Path(reference_dir) / run
        case = load_case(folder / "case.toml", {"case.calibration": NO_CALIBRATION,
                                                 **{k: v for k, v in fixed.items() if k.startswith("popbal.")}})
        regimes[run] = "spread" if plume_spreads(case) else "compact"
        if run not in measurable:
            continue
        radius = channel_closure(case)[0]
        table, _ = measure_clustering(folder, radius)
        measured = interior(table)
        per_run[run] = {"regime": regimes[run], "channel_radius": radius,
                        "collision_radius": measured["collision_radius"], "clustering": measured["clustering"],
                        "equivalent_radius": table.attrs["radius"]}
    excluded = [r for r, v in per_run.items() if not v["clustering"] > 1.0]

    def pooled(regime, leave_out):
        radii = {r: v["collision_radius"] for r, v in per_run.items()
                 if v["regime"] == regime and r not in leave_out and math.isfinite(v["collision_radius"])}
        if not radii:
            return None
        value, se = _geometric_mean_with_error(radii.values())
        return {"value": value, "standard_error": se, "runs": list(radii)}

    compact, spread = pooled("compact", excluded), pooled("spread", excluded)
    left = (f"; excluded (S <= 1): {', '.join(excluded) or 'none'}; no droplet snapshot: "
            f"{', '.join(unmeasured) or 'none'}")
    if compact is None:
        raise MeasureError(f"no compact run of {', '.join(runs) or 'none'} gives the channel's collision radius "
                           f"(compact by the regime rule: "
                           f"{', '.join(r for r in runs if regimes[r] == 'compact') or 'none'}{left})")
    spreading = [r for r in runs if regimes[r] == "spread"]
    if spreading and spread is None:
        raise MeasureError(f"{', '.join(spreading)} spread by the regime rule, and none gives the spread plume's "
                           f"collision radius{left}; the compact plume's would stand for it")
    return {"compact": compact, "spread": spread, "with_excluded": pooled("compact", ()), "per_run": per_run,
            "no_snapshot": unmeasured, "excluded": excluded}


#: Largest relative standard error [-] of a run's stirring diffusivity D_e for it to count in the pooled value: the
#: identifiability gate's own limit. [chosen]
DISPERSION_MAX_ERROR = 0.5


def dispersion_from_suspension(runs, reference_dir: str | Path) -> dict:
    """The outer zone's stirring D [m^2/s] (popbal.outer_dispersion) from :mod:`analysis.suspension`: per run the
    size classes' concentration profiles away from the axis fitted as one stirred suspension, k = k0 + U / D_e
    (:func:`analysis.suspension.settling_fit`); the runs whose 1 / D_e is determined (relative standard error below
    :data:`DISPERSION_MAX_ERROR`) pooled by the inverse-variance mean of 1 / D_e, the fitted coefficient, its
    standard error widened by sqrt(chi^2 per degree of freedom) where the runs scatter more than that. Returns
    {"value", "standard_error", "runs" (pooled), "per_run": {run: (D_e, its standard error)}, "undetermined",
    "no_snapshot" (left out)}; ValueError where no run determines it."""
    from analysis.suspension import measure_suspension, settling_fit

    per_run, undetermined, inverse, weight = {}, [], [], []
    runs, unmeasured = _with_snapshots(runs, reference_dir)
    for run in runs:
        fit = settling_fit(measure_suspension(Path(reference_dir) / run)[0])
        d, se = fit["diffusivity"], fit["diffusivity_error"]
        per_run[run] = (d, se)
        if math.isfinite(d) and math.isfinite(se) and 0.0 < se < DISPERSION_MAX_ERROR * d:
            inverse.append(1.0 / d)
            weight.append((d * d / se) ** 2)  # 1 / se(1 / D)^2, se(1 / D) = se(D) / D^2
        else:
            undetermined.append(run)
    if not inverse:
        raise MeasureError(f"no run of {', '.join(runs) or 'none'} determines the stirring diffusivity (relative "
                           f"standard error below {DISPERSION_MAX_ERROR:g}): it cannot be measured")
    mean = float(np.average(inverse, weights=weight))
    se_inverse = 1.0 / math.sqrt(float(np.sum(weight)))
    if len(inverse) > 1:  # the runs scatter more than their own errors say: widen, as settling_fit does
        chi2 = float(np.sum(np.asarray(weight) * (np.asarray(inverse) - mean) ** 2)) / (len(inverse) - 1)
        se_inverse *= math.sqrt(max(chi2, 1.0))
    return {"value": 1.0 / mean, "standard_error": se_inverse / mean**2, "per_run": per_run,
            "runs": [r for r in runs if r not in undetermined], "undetermined": undetermined,
            "no_snapshot": unmeasured}
