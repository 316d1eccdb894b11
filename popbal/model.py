"""From a case to the reduced model's arrays: grid, zones, feed, slag flow, velocity table, parameters.

:func:`setup` is the one entry point the command line, the tests, the benchmark and the report scripts call
(``popbal.setup("simple", popbal__end_time=10)``); it returns a :class:`Model`, plain data that
:func:`popbal.run` advances. Nothing here is computed twice: settling velocities come from
:func:`settler.derived.settling_velocity`, feed rates from :mod:`settler.physics.feed`, the reaction from
:mod:`settler.physics.matte`.

Zones: index 0 is the channel under the inlet, index 1 the outer zone, index 2 the roof layer under the inlet (only
its top cell is used), index 3 the bottom layer over the floor (only its bottom cell is used); area 0 without
them (see :mod:`popbal.closures`).
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field

import numpy as np

from settler.cases import Case, CaseError, case_with_overrides
from settler.derived import Quantity, plausibility_warnings, settling_velocity
from settler.physics import (COALESCENCE_RULES, PROBABILITY_FORMS, STANDARD_GRAVITY, density_at_age, droplet_rate,
                             relative_diameter_at_age, scale_factor_pdf, stokes_velocity)

from . import closures, limits
from .grid import SectionGrid, make_grid, split_to_pivots, volume_of
from .kernels import merger_speed_limit

ZONES = ("channel", "outer", "roof", "bottom")
CHANNEL, OUTER, ROOF, BOTTOM = 0, 1, 2, 3

#: Velocity-table resolution with reaction: ages 0 ... TABLE_SPAN time constants in steps of 1/TABLE_PER_TAU.
TABLE_PER_TAU = 20
TABLE_SPAN = 12.0

#: Gauss-Legendre points over the scale-factor range of the normal feed distribution.
FEED_QUADRATURE_POINTS = 200


@dataclass(frozen=True)
class Model:
    """Everything a run needs, as arrays and scalars (SI units). Built by :func:`setup`.

    grid: the sections (original droplet volume). cells J, cell_height dz [m], z (J,) cell centres [m].
    zone_area (4,) [m^2]: channel, outer, roof, bottom; the layers' are their volume per cell height (A_L delta / dz
    and A_box h_b / dz), so that their one cell (the top, the bottom) holds the layer's volume (0: no such layer).
    bottom_thickness h_b [m]. roof_thickness delta [m] and roof_coefficient / roof_radius (J,): the roof cell's cloud
    law (c_L, delta in the top cell, 0 below); roof_slag_velocity [m/s]: the slag feed's velocity through the roof
    layer, which enters over the inlet disk (:func:`roof_slag_velocity`; in place of downflow's in the roof cell).
    feed_number_rate (K,) [1/s]: droplets fed per second per section.
    zone_feed_fraction (2,) [-]. feed_multiplier [-] and feed_end [s]: the feed is feed_multiplier x the case's rate
    while t < feed_end. downflow (J,) [m/s]: slag velocity at each cell's lower face; sink_rate (J,) [1/s]: slag
    withdrawal per unit volume. velocity_table (K, M) [m/s] single-droplet settling velocity over age, age_step [s].
    residence_time [s]: slag mass / slag feed rate (inf without slag feed). stop_time [s]: when the run ends.
    return_velocity [m/s]: the outer zone's slag upflow u_up (0: no return flow; popbal.closures.return_velocity).
    return_upflow (J,) [m/s] and exchange_rate (J,) [1/s]: with the circulation's profile (popbal.entrainment_length)
    the outer zone's upflow per cell, u_up s(z), and the rate at which each cell's droplets pass into the channel
    (popbal.closures.circulation_profile, exchange_rates; positive part), and turning_weight (J,) [-] the share of
    the channel's turned droplets each cell takes (the slag the plume gives back there over all it gives back);
    empty without it (u_up everywhere, the turned droplets into the bottom cell).
    cloud_coefficient [-] and cloud_radius [m] (J,): the channel zone's cloud law per cell, the plume's below the
    feed layer and the layer's in it (popbal.closures.cloud_profile).
    """

    case: Case
    grid: SectionGrid
    cells: int
    cell_height: float
    z: np.ndarray
    zone_area: np.ndarray
    channel_radius: float
    inlet_radius: float
    feed_density: float
    feed_number_rate: np.ndarray
    zone_feed_fraction: np.ndarray
    feed_multiplier: float
    feed_end: float
    downflow: np.ndarray
    sink_rate: np.ndarray
    velocity_table: np.ndarray
    age_step: float
    residence_time: float
    stop_time: float
    horizontal: bool
    reacting: bool
    x_initial: float
    x_final: float
    time_constant: float
    viscosity: float
    cloud_coefficient: np.ndarray
    cloud_radius: np.ndarray
    gravity: float = STANDARD_GRAVITY
    parameters: dict = field(default_factory=dict)
    return_velocity: float = 0.0
    roof_thickness: float = 0.0
    roof_coefficient: np.ndarray = field(default_factory=lambda: np.zeros(0))
    roof_radius: np.ndarray = field(default_factory=lambda: np.zeros(0))
    bottom_thickness: float = 0.0
    roof_slag_velocity: float = 0.0
    return_upflow: np.ndarray = field(default_factory=lambda: np.zeros(0))
    exchange_rate: np.ndarray = field(default_factory=lambda: np.zeros(0))
    turning_weight: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def roof(self) -> bool:
        """Whether the model has a roof layer (popbal.closures)."""
        return self.zone_area[ROOF] > 0.0

    @property
    def bottom(self) -> bool:
        """Whether the model has a bottom layer (popbal.closures)."""
        return self.zone_area[BOTTOM] > 0.0

    @property
    def bottom_turning_rate(self) -> float:
        """u_s t / h_b [1/s]: the plume's droplet velocity over the bottom layer's thickness, the rate at which the
        plume turns over it; the layer's shear rate is bottom_shear_coefficient times it (popbal.closures). NaN
        without a bottom layer."""
        if not self.bottom:
            return math.nan
        return self.parameters["plume_velocity"] * self.parameters["transport_factor"] / self.bottom_thickness

    @property
    def name(self) -> str:
        return self.case.case.name

    def numbers(self) -> list[Quantity]:
        """The dimensionless groups and scales of this model, logged at start-up and written to metadata."""
        return start_up_numbers(self)


def setup(case: str | os.PathLike | Case, overrides: dict | list | None = None, **keyword_overrides) -> Model:
    """The reduced model of a case: a preset name, a TOML path or a :class:`settler.cases.Case`.

    Overrides as ``{"popbal.end_time": 10}``, ``["popbal.end_time=10"]`` or keywords ``popbal__end_time=10``.
    Raises :class:`settler.cases.CaseError` naming the key, the value and what is allowed.
    """
    case = case_with_overrides(case, overrides, **keyword_overrides)
    try:
        return build(case)
    except (ZeroDivisionError, OverflowError) as exc:
        # a value far outside what the closures were made for (settler.derived.plausibility_warnings names it)
        outside = [m.group(1) for w in plausibility_warnings(case) if (m := re.search(r"(\w+\.\w+ = [^:]+)", w))]
        raise CaseError(f"the reduced model's closures overflow for this case ({exc}); outside the range the laws "
                        f"were made for: {', '.join(outside) or 'nothing'}") from exc


def build(case: Case) -> Model:
    """Arrays and parameters of the reduced model for a validated case."""
    g, p, f, c = case.geometry, case.popbal, case.feed, case.coalescence
    if case.inlet_is_slot:
        raise CaseError(f"geometry.inlet_length = {g.inlet_length!r} m: popbal models a disk inlet under which one "
                        "axisymmetric channel forms; a slot feeds a row of channels, which the reduced model does not "
                        "represent; allowed: no inlet_length (a disk of inlet_diameter)")
    box_area = g.width * g.depth
    inlet_radius = 0.5 * g.inlet_diameter
    if p.plume_dilution_reynolds and p.channel_radius_form != "flux":
        raise CaseError(f"popbal.plume_dilution_reynolds = {p.plume_dilution_reynolds!r}: dilutes the flux form's "
                        f"plume volume fraction, but popbal.channel_radius_form = "
                        f"{p.channel_radius_form or 'inlet'!r}; allowed: with channel_radius_form = 'flux', or no "
                        "plume_dilution_reynolds")
    channel_radius, plume_velocity, reynolds, transport = channel_closure(case)
    channel_area = math.pi * channel_radius**2
    if channel_area >= box_area:
        raise CaseError(f"popbal.channel_radius_factor = {p.channel_radius_factor!r}: the channel (radius "
                        f"{channel_radius:g} m) must be smaller than the box cross-section {g.width:g} x {g.depth:g} m")
    if p.feed_layer_thickness and p.feed_layer_coefficient is None:
        raise CaseError(f"popbal.feed_layer_thickness = {p.feed_layer_thickness!r} m: needs popbal.feed_layer_coefficient "
                        "(a number >= 0); allowed: give both, or neither (no feed layer)")
    if p.feed_layer_thickness is not None and p.feed_layer_thickness > g.height:
        raise CaseError(f"popbal.feed_layer_thickness = {p.feed_layer_thickness!r} m: allowed at most the slag height "
                        f"geometry.height = {g.height:g} m")
    if channel_area == 0.0 and p.channel_feed_fraction > 0.0:
        raise CaseError(f"popbal.channel_feed_fraction = {p.channel_feed_fraction!r}: allowed 0 when "
                        "popbal.channel_radius_factor = 0 (no channel zone)")
    roof_volume, roof_coefficient, roof_radius = roof_layer(case, channel_area, cells=p.height_cells)
    bottom_thickness = bottom_layer(case, channel_radius)
    zone_area = np.array([channel_area, box_area - channel_area, roof_volume / (g.height / p.height_cells),
                          box_area * bottom_thickness / (g.height / p.height_cells)])

    # sections: original volumes from the smallest fed droplet to the largest a merger may make
    fed_diameters, fed_numbers = feed_points(case)
    top = volume_of(c.size_limit) if c.enabled else volume_of(fed_diameters.max())
    smallest = float(volume_of(fed_diameters.min()))
    check_size(case, smallest, float(top))
    grid = make_grid(smallest, float(top), p.sections_per_doubling)
    feed_number_rate = split_to_pivots(volume_of(fed_diameters), fed_numbers, grid.pivots)

    cells = p.height_cells
    dz = g.height / cells
    z = (np.arange(cells) + 0.5) * dz
    # the droplets' cloud law in the plume carries them at transport x u_s (steady), so its coefficient is c_ch x t^2,
    # times the confined plume's c(R / R_c) under popbal.confinement, which u_s holds (channel_closure)
    law = closures.PLUME_LAWS[p.plume_law or "uniform_core"]
    slag_core = core_radius(case, channel_radius)  # R_s of the confined laws (R_c unless plume_core_radius)
    confined = law(column_radius(case) / slag_core) \
        if p.confinement and plume_velocity > 0.0 and channel_radius > 0.0 else 1.0
    plume_coefficient = p.channel_coefficient * confined * transport**2
    cloud_coefficient, cloud_radius = closures.cloud_profile(z, g.height, channel_radius, plume_coefficient,
                                                             p.feed_layer_thickness, p.feed_layer_coefficient)

    # slag: residence time, and in 'vertical' flow a downflow that the outlet band withdraws
    slag_volume_rate = case.slag.feed_rate / case.slag.density
    residence = residence_time(case)
    horizontal = p.slag_flow == "horizontal"
    faces = np.arange(cells + 1) * dz
    if horizontal or slag_volume_rate == 0.0:
        face_velocity = np.zeros(cells + 1)
    else:
        band_low = g.outlet_height - 0.5 * g.outlet_diameter
        face_velocity = slag_volume_rate / box_area * np.clip((faces - band_low) / g.outlet_diameter, 0.0, 1.0)
    downflow = face_velocity[:-1].copy()
    sink_rate = np.diff(face_velocity) / dz

    feed_end = p.feed_duration if p.feed_duration is not None else math.inf
    feed_multiplier = 1.0
    stop_time = p.end_time
    if horizontal:
        if not math.isfinite(residence):
            raise CaseError("popbal.slag_flow = 'horizontal': needs slag.feed_rate > 0, which sets the residence time "
                            "the column spends in the settler")
        # the column passes under the inlet for the fraction of its residence time that the inlet covers
        inlet_area = math.pi * inlet_radius**2
        feed_multiplier = box_area / inlet_area
        feed_end = min(feed_end, residence * inlet_area / box_area)
        stop_time = min(stop_time, residence)

    reacting = bool(case.reaction.enabled)
    x0 = case.x_initial if reacting else math.nan
    xf = case.x_final if reacting else math.nan
    tau = case.reaction.time_constant
    ages = np.arange(velocity_table_ages(case)) * (tau / TABLE_PER_TAU) if reacting else np.zeros(1)
    table = np.empty((grid.size, ages.size))
    for m, age in enumerate(ages):
        if reacting:
            scale = relative_diameter_at_age(age, x0, xf, tau)
            density = density_at_age(age, x0, xf, tau)
        else:
            scale, density = 1.0, case.matte.density
        for k, d0 in enumerate(grid.diameters):
            table[k, m] = settling_velocity(case, d0 * scale, density)

    # 'step' rule with fixed droplet sizes: the approach speed below which a pair merges, once per pair
    speed_limit = np.empty((0, 0))
    if speed_table_needed(case):
        speed_limit = np.array([[merger_speed_limit(da, db, case.matte.density, case.slag.density,
                                                    case.matte.interfacial_tension, c.psi, c.virtual_mass,
                                                    PROBABILITY_FORMS[c.probability_form], c.threshold)
                                 for db in grid.diameters] for da in grid.diameters])

    parameters = {
        "coalescence": bool(c.enabled),
        "form": PROBABILITY_FORMS[c.probability_form],
        "psi": c.psi,
        "virtual_mass": c.virtual_mass,
        "threshold": c.threshold,
        "rule": COALESCENCE_RULES[p.coalescence_rule],
        "efficiency": p.collision_efficiency,
        "interfacial_tension": case.matte.interfacial_tension,
        "hindered_exponent": p.hindered_exponent,
        "channel_coefficient": plume_coefficient,
        "shear_coefficient": p.shear_coefficient,
        # the roof layer's own kernel and the bottom layer's drainage (popbal.closures); absent: the channel's, none
        "roof_efficiency": p.collision_efficiency if p.roof_collision_efficiency is None
        else p.roof_collision_efficiency,
        "channel_efficiency": channel_efficiency(case, channel_radius),
        # the roof layer's droplets leave it at u_L (+ w) alone ('cloud') or plus their own settling ('sizes')
        "roof_cloud_drainage": p.roof_drainage == "cloud",
        "roof_shear_coefficient": p.shear_coefficient if p.roof_shear_coefficient is None
        else p.roof_shear_coefficient,
        "bottom_shear_coefficient": p.shear_coefficient if p.bottom_shear_coefficient is None
        else p.bottom_shear_coefficient,
        # the plume's discharge pushes the bottom layer's droplets into the floor at bottom_drain_coefficient x the
        # plume's droplet velocity [m/s]
        "bottom_push": (p.bottom_drain_coefficient or 0.0) * plume_velocity * transport,
        # the slag on the axis runs at u_s, the droplets' cloud at transport x u_s
        "axis_velocity_ratio": (1.0 if p.axis_velocity_ratio is None else p.axis_velocity_ratio) / transport,
        "plume_velocity": plume_velocity,
        "plume_reynolds": reynolds,
        "transport_factor": transport,
        "max_courant": p.max_courant,
        "time_step": p.time_step,
        "output_interval": p.output_interval,
        "density_slag": case.slag.density,
        "max_rate_step": 0.5,
        "speed_limit": speed_limit,
        "busy_partners": bool(p.busy_partners),
        "growth_target": c.growth_target,
        "growth_rate": c.growth_rate,
    }
    if p.channel_collision_efficiency is not None and channel_area == 0.0:
        raise CaseError(f"popbal.channel_collision_efficiency = {p.channel_collision_efficiency!r}: sets the kernel "
                        "of a channel zone this case does not have; allowed only with popbal.channel_radius_factor > 0 "
                        "(or leave it out)")
    roof_keys = "popbal.roof_layer_coefficient and popbal.roof_thickness (or popbal.roof_drainage_ratio)"
    for key, layer, needs in (("roof_drainage", roof_volume > 0.0, roof_keys),
                              ("roof_collision_efficiency", roof_volume > 0.0, roof_keys),
                              ("roof_shear_coefficient", roof_volume > 0.0, roof_keys),
                              ("bottom_shear_coefficient", bottom_thickness > 0.0, "popbal.bottom_layer_factor"),
                              ("bottom_drain_coefficient", bottom_thickness > 0.0, "popbal.bottom_layer_factor")):
        if getattr(p, key) is not None and not layer:
            raise CaseError(f"popbal.{key} = {getattr(p, key)!r}: sets a layer this case does not have; allowed only "
                            f"with {needs} (or leave it out)")
    ratio = p.return_flow_ratio or 0.0
    if ratio > 0.0 and (channel_area == 0.0 or zone_area[OUTER] <= 0.0):
        raise CaseError(f"popbal.return_flow_ratio = {ratio!r}: needs a channel zone inside the box "
                        "(popbal.channel_radius_factor > 0); allowed: 0 without one")
    if p.confinement and ratio > 0.0:  # r multiplies the confined Stokes plume's return share S(R / R_c)
        ratio *= closures.confined_return_share(column_radius(case) / slag_core)
    return_velocity = closures.return_velocity(ratio, plume_velocity)
    if p.outer_dispersion and not return_velocity > 0.0:
        raise CaseError(f"popbal.outer_dispersion = {p.outer_dispersion!r} m^2/s: stirs a return flow this case does "
                        "not have; allowed only with popbal.return_flow_ratio > 0 (or leave it out)")
    parameters["outer_dispersion"] = float(p.outer_dispersion or 0.0)
    parameters["bottom_lift"], parameters["bottom_lift_velocity"] = bottom_lift(case, bottom_thickness,
                                                                                return_velocity)
    parameters["bottom_turning"] = bottom_turning(case, bottom_thickness, return_velocity)
    if p.bottom_turning_form is not None and not parameters["bottom_turning"]:
        raise CaseError(f"popbal.bottom_turning_form = {p.bottom_turning_form!r}: shapes a turn this case does not "
                        "make; allowed only with popbal.bottom_turning_share > 0 (or leave it out)")
    parameters["bottom_turning_uniform"] = p.bottom_turning_form == "uniform"
    return_upflow, exchange_rate, turning_weight = circulation(case, z, dz, return_velocity)
    return Model(case=case, grid=grid, cells=cells, cell_height=dz, z=z, zone_area=zone_area,
                 channel_radius=channel_radius, inlet_radius=inlet_radius, feed_density=case.matte.density,
                 feed_number_rate=feed_number_rate,
                 zone_feed_fraction=np.array([p.channel_feed_fraction, 1.0 - p.channel_feed_fraction]),
                 feed_multiplier=feed_multiplier, feed_end=feed_end, downflow=downflow, sink_rate=sink_rate,
                 velocity_table=table, age_step=tau / TABLE_PER_TAU, residence_time=residence, stop_time=stop_time,
                 horizontal=horizontal, reacting=reacting, x_initial=x0, x_final=xf, time_constant=tau,
                 viscosity=case.slag_viscosity, cloud_coefficient=cloud_coefficient, cloud_radius=cloud_radius,
                 parameters=parameters, return_velocity=return_velocity, roof_thickness=float(roof_radius[-1]),
                 roof_coefficient=roof_coefficient, roof_radius=roof_radius, bottom_thickness=bottom_thickness,
                 roof_slag_velocity=roof_slag_velocity(case, roof_volume > 0.0, horizontal),
                 return_upflow=return_upflow, exchange_rate=exchange_rate, turning_weight=turning_weight)


def bottom_lift(case: Case, bottom_thickness: float, return_velocity: float) -> tuple[float, float]:
    """(lambda [-], u_b [m/s]) of the bottom layer's lift into the return flow (popbal.closures,
    :func:`popbal.closures.lift_share`): ``bottom_lift_share`` and u_b = ``bottom_lift_velocity_ratio`` x u_up; (0, 0)
    without it. Refuses (CaseError) the keys where the case has no bottom layer or no return flow to lift into, and
    either key without the other."""
    p = case.popbal
    share, ratio = p.bottom_lift_share, p.bottom_lift_velocity_ratio
    if not share:
        if ratio is not None:
            raise CaseError(f"popbal.bottom_lift_velocity_ratio = {ratio!r}: sets the lift of popbal.bottom_lift_share,"
                            " which is absent or 0; allowed only with it (or leave it out)")
        return 0.0, 0.0
    if ratio is None:
        raise CaseError(f"popbal.bottom_lift_share = {share!r}: needs popbal.bottom_lift_velocity_ratio (a number > 0:"
                        " the upflow at the bottom layer's top over the return flow's u_up)")
    if not bottom_thickness > 0.0:
        raise CaseError(f"popbal.bottom_lift_share = {share!r}: lifts droplets out of a bottom layer this case does "
                        "not have; allowed only with popbal.bottom_layer_factor (or leave it out)")
    if not return_velocity > 0.0:
        raise CaseError(f"popbal.bottom_lift_share = {share!r}: lifts droplets into a return flow this case does not "
                        "have; allowed only with popbal.return_flow_ratio > 0 (or leave it out)")
    return float(share), ratio * return_velocity


def circulation(case: Case, z: np.ndarray, cell_height: float, return_velocity: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(the outer zone's upflow per cell [m/s], its cells' exchange rate into the channel [1/s], the share of the
    channel's turned droplets each cell takes [-]: where the plume gives slag back, in proportion) of the return
    flow's circulation (popbal.closures.circulation_profile, exchange_rates; ``entrainment_length`` and
    ``turning_length``); three empty arrays without them. Refuses (CaseError) either key without the other or
    without a return flow."""
    p = case.popbal
    a, b = p.entrainment_length, p.turning_length
    if a is None and b is None:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    if a is None or b is None:
        key, missing = ("entrainment_length", "turning_length") if b is None else ("turning_length",
                                                                                  "entrainment_length")
        raise CaseError(f"popbal.{key} = {a if b is None else b!r}: needs popbal.{missing} (a number > 0, in column "
                        "radii) as well: the circulation's profile takes both")
    if not return_velocity > 0.0:
        raise CaseError(f"popbal.entrainment_length = {a!r}: shapes a return flow this case does not have; allowed "
                        "only with popbal.return_flow_ratio > 0 (or leave it out)")
    upflow = return_velocity * closures.circulation_profile(z, case.geometry.height, column_radius(case), a, b)
    rates = closures.exchange_rates(upflow, cell_height)
    given = np.maximum(-rates, 0.0)  # cell 0's: the slag turning over the floor into it
    return upflow, np.maximum(rates, 0.0), given / given.sum()


def bottom_turning(case: Case, bottom_thickness: float, return_velocity: float) -> float:
    """``bottom_turning_share`` [-] (0 without it): the share of the channel's droplets slower than the return flow
    that turn into it at the channel's bottom instead of entering the bottom layer (popbal.closures). Refuses
    (CaseError) the key where the case has no bottom layer or no return flow."""
    share = case.popbal.bottom_turning_share
    if not share:
        return 0.0
    if not bottom_thickness > 0.0:
        raise CaseError(f"popbal.bottom_turning_share = {share!r}: turns droplets away from a bottom layer this case "
                        "does not have (without one the channel's slow droplets all turn); allowed only with "
                        "popbal.bottom_layer_factor (or leave it out)")
    if not return_velocity > 0.0:
        raise CaseError(f"popbal.bottom_turning_share = {share!r}: turns droplets into a return flow this case does "
                        "not have; allowed only with popbal.return_flow_ratio > 0 (or leave it out)")
    return float(share)


def roof_slag_velocity(case: Case, roof: bool, horizontal: bool) -> float:
    """The slag's downward velocity through the roof layer [m/s]: the slag feed's volume rate over the inlet disk,
    where fulldem's velocity inlet brings it in (popbal.closures, roof layer); 0 without a roof, without slag feed
    or in 'horizontal' slag flow (the column model, whose slag moves sideways)."""
    rate = case.slag.feed_rate / case.slag.density
    if not roof or horizontal or rate == 0.0:
        return 0.0
    return rate / (math.pi * (0.5 * case.geometry.inlet_diameter) ** 2)


def bottom_layer(case: Case, channel_radius: float) -> float:
    """The bottom layer's thickness h_b = popbal.bottom_layer_factor x R_c [m]; 0 without a bottom layer. CaseError
    without a channel or where the layer would fill half the height."""
    p, g = case.popbal, case.geometry
    if p.bottom_layer_factor is None:
        return 0.0
    if channel_radius == 0.0:
        raise CaseError(f"popbal.bottom_layer_factor = {p.bottom_layer_factor!r}: the bottom layer's thickness is "
                        "set by the channel radius; allowed only with a channel zone (popbal.channel_radius_factor > 0)")
    thickness = p.bottom_layer_factor * channel_radius
    if thickness > g.height / 2:
        raise CaseError(f"popbal.bottom_layer_factor = {p.bottom_layer_factor!r}: the bottom layer ({thickness:.4g} m "
                        f"thick) would fill more than half the slag height geometry.height = {g.height:g} m")
    return thickness


def roof_layer(case: Case, channel_area: float, cells: int) -> tuple[float, np.ndarray, np.ndarray]:
    """(volume A_L delta [m^3], cloud coefficient (J,) [-], cloud length (J,) [m]) of the roof layer: the inlet
    disk's area A_L times its thickness delta (:func:`roof_thickness`), with c_L and delta in the top cell and 0
    below; volume 0 and zero arrays without a roof layer. CaseError where the keys do not go together."""
    p, g = case.popbal, case.geometry
    coefficient, radius = np.zeros(cells), np.zeros(cells)
    thickness = roof_thickness(case)
    if thickness == 0.0:
        return 0.0, coefficient, radius
    if channel_area == 0.0 or p.channel_feed_fraction == 0.0:
        raise CaseError(f"popbal.roof_layer_coefficient = {p.roof_layer_coefficient!r}: the roof layer drains into the "
                        "channel and takes its feed; allowed only with a channel zone (popbal.channel_radius_factor "
                        "> 0 and popbal.channel_feed_fraction > 0)")
    if p.feed_layer_thickness:
        raise CaseError(f"popbal.feed_layer_thickness = {p.feed_layer_thickness!r} m: the channel's feed layer and the "
                        "roof layer describe the same layer; allowed: one of them")
    coefficient[-1], radius[-1] = p.roof_layer_coefficient, thickness
    return math.pi * (0.5 * g.inlet_diameter) ** 2 * thickness, coefficient, radius


def roof_thickness(case: Case) -> float:
    """The roof layer's thickness delta [m]: popbal.roof_thickness ('fixed', the default form) or the drainage law's
    (popbal.roof_thickness_form = 'drainage': :func:`popbal.closures.roof_drainage_thickness` with the matte feed
    over the inlet disk, the Stokes velocity of the mean fed droplet and the slag's velocity through the roof); 0
    without a roof layer. CaseError where the keys do not go together or the layer would fill half the height."""
    p, g = case.popbal, case.geometry
    drainage = p.roof_thickness_form == "drainage"
    if drainage and p.roof_thickness is not None:
        raise CaseError(f"popbal.roof_thickness = {p.roof_thickness!r}: roof_thickness_form = 'drainage' sets the "
                        "thickness from popbal.roof_drainage_ratio; allowed: one of them")
    if drainage and p.roof_drainage_ratio is None:
        raise CaseError("popbal.roof_thickness_form = 'drainage': needs popbal.roof_drainage_ratio (k, 2.3-2.8 in the "
                        "resolved reference runs); allowed: give it, or the form 'fixed' with popbal.roof_thickness")
    if not drainage and p.roof_drainage_ratio is not None:
        raise CaseError(f"popbal.roof_drainage_ratio = {p.roof_drainage_ratio!r}: belongs to roof_thickness_form = "
                        f"'drainage' (now {p.roof_thickness_form or 'fixed'!r}); allowed: set that form, or leave the "
                        "ratio out")
    given = p.roof_drainage_ratio if drainage else p.roof_thickness
    name = "roof_drainage_ratio" if drainage else "roof_thickness"
    if p.roof_layer_coefficient is None and given is None:
        return 0.0
    allowed = f"allowed: give popbal.roof_layer_coefficient and popbal.{name}, or neither (no roof layer)"
    if p.roof_layer_coefficient is None:
        raise CaseError(f"popbal.{name} = {given!r}: needs popbal.roof_layer_coefficient; {allowed}")
    if given is None:
        raise CaseError(f"popbal.roof_layer_coefficient = {p.roof_layer_coefficient!r}: needs popbal.{name}; {allowed}")
    if drainage:
        drho = case.matte.density - case.slag.density
        mu = case.slag_viscosity
        inlet = math.pi * (0.5 * g.inlet_diameter) ** 2
        flux = case.feed.mass_rate / case.matte.density / inlet
        stokes = stokes_velocity(case.feed.mean_diameter, case.matte.density, case.slag.density, mu)
        slag = roof_slag_velocity(case, True, case.popbal.slag_flow == "horizontal")
        try:
            thickness = closures.roof_drainage_thickness(flux, stokes, p.roof_drainage_ratio, drho, mu,
                                                         p.roof_layer_coefficient, STANDARD_GRAVITY, slag)
        except ValueError as exc:
            raise CaseError(f"popbal.roof_drainage_ratio = {p.roof_drainage_ratio!r}: {exc}") from None
    else:
        thickness = p.roof_thickness
    if thickness > g.height / 2:
        raise CaseError(f"popbal.{name} = {given!r}: the roof layer ({thickness:.4g} m thick) would fill more than "
                        f"half the slag height geometry.height = {g.height:g} m")
    return thickness


def channel_efficiency(case: Case, channel_radius: float) -> float:
    """The plume channel's collision efficiency E_ch [-] (popbal.closures): channel_collision_efficiency, or with
    channel_collision_radius b collision_efficiency x max(1, (R_c / b)^2) (the droplets collide as if mixed over
    the disk of radius b, or over the channel where it is narrower; spread_channel_collision_radius in place of b
    where the plume spreads), else collision_efficiency. CaseError where the keys do not go together."""
    p = case.popbal
    if p.channel_collision_radius is not None and p.channel_collision_efficiency is not None:
        raise CaseError(f"popbal.channel_collision_radius = {p.channel_collision_radius!r} m with "
                        f"popbal.channel_collision_efficiency = {p.channel_collision_efficiency!r}: both set the "
                        "channel's kernel; allowed: one of them")
    if p.spread_channel_collision_radius is not None and (p.channel_collision_radius is None
                                                          or p.spread_flux_reynolds is None):
        raise CaseError(f"popbal.spread_channel_collision_radius = {p.spread_channel_collision_radius!r} m: the "
                        "spread plume's collision radius; allowed only with popbal.channel_collision_radius and "
                        "popbal.spread_flux_reynolds (or leave it out)")
    if p.channel_collision_radius is None:
        return p.collision_efficiency if p.channel_collision_efficiency is None else p.channel_collision_efficiency
    if channel_radius == 0.0:
        raise CaseError(f"popbal.channel_collision_radius = {p.channel_collision_radius!r} m: sets the kernel of a "
                        "channel zone this case does not have; allowed only with popbal.channel_radius_factor > 0 "
                        "(or leave it out)")
    radius = p.channel_collision_radius
    if p.spread_channel_collision_radius is not None and plume_spreads(case):
        radius = p.spread_channel_collision_radius
    return p.collision_efficiency * max(1.0, (channel_radius / radius) ** 2)  # mixed over min(b, R_c)


def core_radius(case: Case, channel_radius: float | None = None) -> float | None:
    """The plume's slag core radius R_s [m] of the confined plume's laws (popbal.closures): popbal.plume_core_radius
    R_0 (:func:`compact_core_radius`: with plume_core_exponent, grown with the feed Reynolds number), or
    spread_core_share x the column radius R where the feed Reynolds number rho_s Q_ch / (mu L) reaches
    spread_flux_reynolds, or plume_core_column_share x R for a compact plume whose inlet radius reaches
    plume_fill_inlet_share x R, and no more than plume_core_column_share x R; without plume_core_radius the channel
    radius R_c (None when not given). CaseError where the keys do not go together."""
    p = case.popbal
    spread = (p.spread_flux_reynolds, p.spread_core_share)
    if p.spread_reference_radius is not None and p.plume_core_radius is None:
        raise CaseError(f"popbal.spread_reference_radius = {p.spread_reference_radius!r} m: the length of the regime "
                        "rule's feed Reynolds number; allowed only with popbal.plume_core_radius and "
                        "popbal.spread_flux_reynolds (or leave it out)")
    for key, value in (("plume_core_column_share", p.plume_core_column_share),
                       ("spread_flux_reynolds", p.spread_flux_reynolds), ("spread_core_share", p.spread_core_share),
                       ("plume_core_exponent", p.plume_core_exponent), ("plume_core_reynolds", p.plume_core_reynolds),
                       ("plume_fill_inlet_share", p.plume_fill_inlet_share)):
        if value is not None and p.plume_core_radius is None:
            raise CaseError(f"popbal.{key} = {value!r}: bounds or replaces the slag core popbal.plume_core_radius; "
                            "allowed only with it (or leave it out)")
    if (spread[0] is None) != (spread[1] is None):
        raise CaseError(f"popbal.spread_flux_reynolds = {spread[0]!r} with popbal.spread_core_share = {spread[1]!r}: "
                        "allowed: both (a spread plume's core over the column) or neither")
    if p.plume_core_radius is None:
        return channel_radius
    spreads = plume_spreads(case)  # refuses spread_reference_radius without spread_flux_reynolds
    column = column_radius(case)
    compact = compact_core_radius(case)  # checks the law's keys whatever the regime
    core = p.spread_core_share * column if spreads else compact
    if p.plume_fill_inlet_share is not None and p.plume_core_column_share is None:
        raise CaseError(f"popbal.plume_fill_inlet_share = {p.plume_fill_inlet_share!r}: a compact plume whose inlet "
                        "fills the column takes the core popbal.plume_core_column_share x R; allowed only with "
                        "plume_core_column_share (or leave it out)")
    if p.plume_fill_inlet_share is not None and not spreads \
            and 0.5 * case.geometry.inlet_diameter >= p.plume_fill_inlet_share * column:
        core = p.plume_core_column_share * column  # the feed enters over (nearly) the whole column
    if p.plume_core_column_share is not None:
        core = min(core, p.plume_core_column_share * column)
    if core >= column:
        raise CaseError(f"popbal.plume_core_radius = {p.plume_core_radius!r} m: the slag core ({core:.4g} m) must be "
                        f"narrower than the column's equivalent radius {column:.4g} m, where the confined plume has a "
                        "return flow; allowed: a smaller plume_core_radius, plume_core_column_share or "
                        "spread_core_share" + (", or a law (plume_core_exponent, plume_core_reynolds) that keeps "
                                               "the core narrower" if p.plume_core_exponent is not None else ""))
    return core


def compact_core_radius(case: Case) -> float:
    """The compact plume's slag core [m]: popbal.plume_core_radius R_0, or with plume_core_exponent n
    R_0 (Re_Q / Re_Q,0)^n, Re_Q = rho_s Q_ch / (mu L) the feed Reynolds number at L = spread_reference_radius and
    Re_Q,0 = plume_core_reynolds (popbal.closures). CaseError where the keys do not go together."""
    p = case.popbal
    if (p.plume_core_exponent is None) != (p.plume_core_reynolds is None):
        raise CaseError(f"popbal.plume_core_exponent = {p.plume_core_exponent!r} with popbal.plume_core_reynolds = "
                        f"{p.plume_core_reynolds!r}: allowed: both (the compact core's growth with the feed Reynolds "
                        "number) or neither")
    if p.plume_core_exponent is None:
        return p.plume_core_radius
    if p.plume_core_radius is None or p.spread_reference_radius is None:
        raise CaseError(f"popbal.plume_core_exponent = {p.plume_core_exponent!r}: the growth of the slag core "
                        "popbal.plume_core_radius with the feed Reynolds number rho_s Q / (mu L), L = "
                        "popbal.spread_reference_radius (which needs spread_flux_reynolds and spread_core_share); "
                        "allowed only with both (or leave it out)")
    reynolds = closures.feed_reynolds(channel_volume_flux(case), p.spread_reference_radius, case.slag.density,
                                      case.slag_viscosity)
    if reynolds <= 0.0:  # no feed: the core at its reference (it carries no load)
        return p.plume_core_radius
    return p.plume_core_radius * (reynolds / p.plume_core_reynolds) ** p.plume_core_exponent


def channel_volume_flux(case: Case) -> float:
    """Q_ch [m^3/s]: the matte feed's volume rate that enters the channel (popbal.channel_feed_fraction of it)."""
    return case.feed.mass_rate * case.popbal.channel_feed_fraction / case.matte.density


def plume_spreads(case: Case) -> bool:
    """The slag core's regime (popbal.closures): True where popbal.spread_flux_reynolds is given and the feed
    Reynolds number rho_s Q_ch / (mu L) reaches it, L = popbal.spread_reference_radius, else popbal.plume_core_radius
    R_0. CaseError for spread_reference_radius without spread_flux_reynolds."""
    p = case.popbal
    if p.spread_reference_radius is not None and p.spread_flux_reynolds is None:
        raise CaseError(f"popbal.spread_reference_radius = {p.spread_reference_radius!r} m: the length of the regime "
                        "rule's feed Reynolds number; allowed only with popbal.spread_flux_reynolds (or leave it out)")
    length = p.plume_core_radius if p.spread_reference_radius is None else p.spread_reference_radius
    return p.spread_flux_reynolds is not None and closures.feed_reynolds(
        channel_volume_flux(case), length, case.slag.density, case.slag_viscosity) >= p.spread_flux_reynolds


def column_radius(case: Case) -> float:
    """R = sqrt(W D / pi) [m]: the radius of the column with the box's cross-section (the confined plume's wall)."""
    return math.sqrt(case.geometry.width * case.geometry.depth / math.pi)


def channel_closure(case: Case) -> tuple[float, float, float, float]:
    """(R_c [m], u_s [m/s], Re [-], transport factor [-]) of the case's channel (popbal.closures).

    R_c: channel_radius_factor inlet radii ('inlet' form, the default), channel_radius_factor sqrt(Q_ch / (pi u_s))
    ('flux') or channel_radius ('fixed'); u_s = sqrt(c_ch Q_ch drho g / (pi mu)) the steady plume velocity of the
    matte feed Q_ch [m^3/s] that enters the channel, with c_ch times the confined plume's c(R / R_c) under ``popbal.confinement``, of the law
    ``popbal.plume_law`` (popbal.closures.PLUME_LAWS; solved with R_c by popbal.closures.confined_closure); Re = rho_s u_s R_c / mu; transport factor 1 / (1 + Re / plume_reynolds_scale) (1 without).
    """
    p, g = case.popbal, case.geometry
    volume_flux = channel_volume_flux(case)
    excess = case.matte.density - case.slag.density
    if p.plume_law and not p.confinement:
        raise CaseError(f"popbal.plume_law = {p.plume_law!r}: the law of the confined plume's coefficient; allowed "
                        "only with popbal.confinement = true (or leave it out)")

    if (p.channel_radius_form == "fixed") != (p.channel_radius is not None):
        raise CaseError(f"popbal.channel_radius = {p.channel_radius!r} m with popbal.channel_radius_form = "
                        f"{p.channel_radius_form or 'inlet'!r}: allowed: both together (a fixed channel radius), or "
                        "neither")

    if p.plume_core_radius is not None and not p.confinement:
        raise CaseError(f"popbal.plume_core_radius = {p.plume_core_radius!r} m: the slag core of the confined plume's "
                        "laws; allowed only with popbal.confinement = true (or leave it out)")
    core = core_radius(case)

    def radius_of(velocity):  # the droplets' channel, inside the slag core where one is given
        radius = droplet_radius_of(velocity)
        return radius if core is None else min(radius, core)

    def droplet_radius_of(velocity):
        if p.channel_radius_form == "fixed":
            return p.channel_radius if p.channel_radius_factor > 0.0 else 0.0
        if p.channel_radius_form == "flux" and p.plume_dilution_reynolds:  # no wider than the inlet that feeds it
            return min(closures.diluted_channel_radius(volume_flux, velocity, p.channel_radius_factor,
                                                       p.plume_dilution_reynolds, case.slag.density,
                                                       case.slag_viscosity), 0.5 * g.inlet_diameter)
        if p.channel_radius_form == "flux":
            return closures.flux_channel_radius(volume_flux, velocity, p.channel_radius_factor)
        return p.channel_radius_factor * 0.5 * g.inlet_diameter

    if p.confinement and volume_flux > 0.0 and excess > 0.0 and p.channel_radius_factor > 0.0:
        try:
            velocity, radius = closures.confined_closure(volume_flux, excess, case.slag_viscosity,
                                                         p.channel_coefficient, column_radius(case), radius_of,
                                                         law=closures.PLUME_LAWS[p.plume_law or "uniform_core"],
                                                         core_radius=core)
        except ValueError as exc:
            raise CaseError(f"popbal.confinement = true: {exc}; allowed: a channel narrower than the box (a smaller "
                            "popbal.channel_radius_factor), or confinement = false") from None
    else:
        velocity = closures.steady_channel_velocity(volume_flux, excess, case.slag_viscosity, p.channel_coefficient) \
            if volume_flux > 0.0 and excess > 0.0 else 0.0
        radius = radius_of(velocity)
    reynolds = closures.plume_reynolds(velocity, radius, case.slag.density, case.slag_viscosity)
    return radius, velocity, reynolds, closures.transport_factor(reynolds, p.plume_reynolds_scale)


def check_size(case: Case, volume_min: float, volume_top: float) -> dict[str, float]:
    """Refuse (CaseError) a case whose run would write more than limits.MAX_OUTPUTS outputs or whose arrays would
    take more memory than limits.memory_limit(); called by :func:`build` before it allocates anything that scales.

    Returns the estimate by part [bytes] (popbal.limits.estimate).
    """
    p = case.popbal
    stop = min(p.end_time, residence_time(case)) if p.slag_flow == "horizontal" else p.end_time
    outputs = limits.check_outputs(stop, p.output_interval, "popbal.output_interval", "popbal.end_time", p.end_time)
    sections = limits.section_estimate(volume_min, volume_top, p.sections_per_doubling)
    return limits.check(p.height_cells, p.sections_per_doubling, sections, outputs, velocity_table_ages(case),
                        speed_table_needed(case), "popbal.output_interval", p.output_interval)


def residence_time(case: Case) -> float:
    """Slag residence time [s]: box slag volume / slag volume feed (inf without slag feed)."""
    g = case.geometry
    slag_volume_rate = case.slag.feed_rate / case.slag.density
    return g.width * g.depth * g.height / slag_volume_rate if slag_volume_rate > 0.0 else math.inf


def velocity_table_ages(case: Case) -> int:
    """Columns M of the velocity table: ages 0 ... TABLE_SPAN time constants with reaction, else one."""
    return int(TABLE_SPAN * TABLE_PER_TAU) + 1 if case.reaction.enabled else 1


def speed_table_needed(case: Case) -> bool:
    """Whether build tabulates merger_speed_limit per section pair ('step' rule, coalescence on, no reaction)."""
    return bool(case.coalescence.enabled and case.popbal.coalescence_rule == "step" and not case.reaction.enabled)


def feed_points(case: Case) -> tuple[np.ndarray, np.ndarray]:
    """Fed droplet diameters [m] and number rates [1/s] that deliver exactly feed.mass_rate.

    'normal': Gauss-Legendre quadrature of the truncated-normal scale factor (settler.physics.scale_factor_pdf) over
    [scale_min, scale_max], so the number rate equals settler.physics.droplet_rate to quadrature accuracy.
    'table': the listed diameters with their mass fractions (e.g. physics.md section 1, Jylha et al. 2020).
    """
    f = case.feed
    density = case.matte.density
    if f.distribution == "table":
        diameters = np.asarray(f.table_diameters, dtype=float)
        mass_share = np.asarray(f.table_mass_fractions, dtype=float)
        mass_share = mass_share / mass_share.sum()
        return diameters, f.mass_rate * mass_share / (density * volume_of(diameters))
    if f.scale_std == 0.0:
        diameters = np.array([f.mean_diameter])
        return diameters, np.array([f.mass_rate / (density * volume_of(f.mean_diameter))])
    nodes, weights = np.polynomial.legendre.leggauss(FEED_QUADRATURE_POINTS)
    s = 0.5 * (f.scale_max - f.scale_min) * nodes + 0.5 * (f.scale_max + f.scale_min)
    w = 0.5 * (f.scale_max - f.scale_min) * weights * scale_factor_pdf(s, f.scale_std, f.scale_min, f.scale_max)
    diameters = f.mean_diameter * s
    masses = density * volume_of(diameters)
    return diameters, f.mass_rate * w / np.sum(w * masses)


def start_up_numbers(model: Model) -> list[Quantity]:
    """Scales and dimensionless groups of the reduced model (logged at start-up, written to metadata.json)."""
    case, grid = model.case, model.grid
    f = case.feed
    q_total = f.mass_rate / model.feed_density
    excess = model.feed_density - case.slag.density
    out = [
        Quantity("sections", grid.size, "-", f"pivot ratio {grid.ratio:.4f}, {grid.diameters[0] * 1e6:.4g} to "
                                              f"{grid.diameters[-1] * 1e6:.4g} um (original diameter)"),
        Quantity("height cells", model.cells, "-", f"dz = {model.cell_height * 1e3:.4g} mm"),
        Quantity("droplets fed per second", float(model.feed_number_rate.sum()), "1/s",
                 f"{f.distribution} distribution"),
        Quantity("slag residence time", model.residence_time, "s", "box slag volume / slag volume feed"),
    ]
    if f.distribution == "normal" and f.mass_rate > 0.0:
        shared = droplet_rate(f.mass_rate, f.mean_diameter, model.feed_density, f.scale_std, f.scale_min, f.scale_max)
        out.append(Quantity("droplets fed per second, shared droplet_rate", shared, "1/s", "settler.physics.feed"))
    q_channel = q_total * model.zone_feed_fraction[CHANNEL]
    if model.zone_area[CHANNEL] > 0.0 and q_channel > 0.0:
        coefficient = model.parameters["channel_coefficient"]
        u_c = closures.steady_channel_velocity(q_channel, excess, model.viscosity, coefficient)
        phi = closures.steady_channel_fraction(q_channel, model.channel_radius, u_c)
        out += [
            Quantity("steady channel velocity u_c", u_c, "m/s", "sqrt(c_ch Q_ch drho g / (pi mu))"),
            Quantity("steady channel volume fraction", phi, "-", "Q_ch / (pi R_c^2 u_c)"),
            Quantity("plume Reynolds number", closures.plume_reynolds(u_c, model.channel_radius, case.slag.density,
                                                                      model.viscosity), "-", "rho_s u_c R_c / mu"),
            Quantity("plume slag velocity u_s", model.parameters["plume_velocity"], "m/s",
                     "sqrt(c_ch Q_ch drho g / (pi mu)) with the case's c_ch; u_c = transport factor x u_s"),
            Quantity("plume Reynolds number of u_s", model.parameters["plume_reynolds"], "-", "rho_s u_s R_c / mu"),
            Quantity("droplet transport factor", model.parameters["transport_factor"], "-",
                     "1 / (1 + Re / popbal.plume_reynolds_scale); 1 without"),
            Quantity("feed layer velocity u_L (steady, dilute)", _layer_velocity(model, q_channel, excess), "m/s",
                     "sqrt(c_L j drho g / mu) delta, j = Q_ch / (pi R_c^2); nan without a feed layer"),
            Quantity("roof layer's steady matte per unit area", _roof_inventory(model, q_channel, excess), "m",
                     "(c_L drho g / mu) I^2 + (w / delta) I = j, j = Q_ch / inlet area, w the slag's velocity "
                     "through it; nan without a roof layer"),
            Quantity("slag velocity through the roof layer w", model.roof_slag_velocity if model.roof else math.nan,
                     "m/s", "slag feed over the inlet disk; nan without a roof layer"),
            Quantity("bottom layer thickness h_b", model.bottom_thickness if model.bottom else math.nan, "m",
                     "bottom_layer_factor x R_c; nan without a bottom layer"),
            Quantity("channel shear rate G", model.parameters["shear_coefficient"] * u_c / model.channel_radius,
                     "1/s", "shear_coefficient u_c / R_c"),
            Quantity("Courant number of u_c at time_step", u_c * model.parameters["time_step"] / model.cell_height,
                     "-", "implicit transport: accuracy, not stability"),
        ]
    v = model.velocity_table[:, 0]
    out += [
        Quantity("settling velocity, smallest section", float(v[0]), "m/s", f"{case.drag.law} drag, fresh matte"),
        Quantity("settling velocity, largest section", float(v[-1]), "m/s", f"{case.drag.law} drag, fresh matte"),
        Quantity("crossing time of the smallest section", case.geometry.height / float(v[0]), "s", "H / v"),
    ]
    if model.horizontal:
        out.append(Quantity("feed window of the column", model.feed_end, "s",
                            "residence time x inlet area / box area"))
    return out


def _layer_velocity(model: Model, volume_flux: float, excess_density: float) -> float:
    """Steady feed-layer velocity u_L = sqrt(c_L j drho g / mu) delta [m/s] (popbal.closures), nan without a layer."""
    p = model.case.popbal
    if not p.feed_layer_thickness:
        return math.nan
    j = volume_flux / model.zone_area[CHANNEL]
    return math.sqrt(p.feed_layer_coefficient * j * excess_density * model.gravity / model.viscosity) \
        * p.feed_layer_thickness


def _roof_inventory(model: Model, volume_flux: float, excess_density: float) -> float:
    """The roof layer's steady, dilute matte volume per unit area [m] (popbal.closures.roof_inventory)."""
    if not model.roof:
        return math.nan
    flux = volume_flux / (math.pi * model.inlet_radius**2)
    return closures.roof_inventory(flux, excess_density, model.viscosity, model.case.popbal.roof_layer_coefficient,
                                   model.gravity, model.roof_slag_velocity, model.roof_thickness)
