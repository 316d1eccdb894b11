"""Running the reduced model: the time loop, the bookkeeping and the result (time series + distributions).

One step of length dt (operator splitting, first order):

1. droplet properties of every cell from the state at the step start (popbal.kernels.cell_properties);
2. dt = min(popbal.time_step, max_courant dz / fastest occupied section, time to the next output or feed change);
3. transport in z with the feed at the top, the settled flux at the bottom and the outlet sink (implicit upwind);
4. coalescence in every occupied cell (cell-average technique, Heun sub-steps);
5. ageing and reaction (the shared reaction fit, exact over the step).

Every amount that enters or leaves the slag is booked per section (fed, settled, lost) and the reaction's FeS
removal as reacted, so fed = in slag + settled + lost + reacted holds to round-off.

Outputs (:class:`Result`, written by :meth:`Result.save`):

* ``timeseries.csv``: exactly the columns of settler.output.TIME_SERIES (NaN where the reduced model has none);
* ``distribution.npz``: arrays listed in :data:`DISTRIBUTION_ARRAYS` with their units (``save(out,
  distribution=False)`` leaves it out);
* ``case.toml`` and ``metadata.json`` (settler.output.write_run_metadata) with the start-up numbers.
"""

from __future__ import annotations

import io
import math
import numbers
import os
import sys
import time as wallclock
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from settler.cases import Case
from settler.output import (CHANNEL_PROFILE, MERGES_BY_HEIGHT, MID_BAND, atomic_write_bytes, band_edges,
                            time_series_frame, write_channel_profile, write_run_metadata, write_table,
                            write_time_series)

from . import limits
from .closures import lift_share, settling_share, turning_share
from .kernels import (AGE, FES_REMOVED, NEGLIGIBLE_VOLUME_FRACTION, NUMBER, QUANTITIES, cell_properties,
                      coalesce_zone, react_zone, transport_two_way, transport_zone)
from .model import BOTTOM, CHANNEL, OUTER, ROOF, ZONES, Model, setup

#: Arrays of distribution.npz: name -> (unit, meaning). T outputs, Z = 4 zones (popbal.model.ZONES), J cells, K
#: sections.
DISTRIBUTION_ARRAYS: dict[str, tuple[str, str]] = {
    "time": ("s", "(T,) output times"),
    "z": ("m", "(J,) cell-centre heights above the bottom of the slag"),
    "zone_area": ("m^2", "(Z,) horizontal area of the channel and outer zones; the roof and bottom layers' volume per "
                         "cell height (each layer's one cell holds it; 0: no such layer)"),
    "original_volume": ("m^3", "(K,) pivot volumes of the sections (droplet volume at the feed composition)"),
    "original_diameter": ("m", "(K,) pivot diameters of the sections at the feed composition"),
    "number_density": ("1/m^3", "(T, Z, J, K) droplets per m^3 of slag"),
    "diameter": ("m", "(T, Z, J, K) actual droplet diameter after reaction (NaN where empty)"),
    "mean_age": ("s", "(T, Z, J, K) volume-weighted mean droplet age (NaN where empty)"),
    "fed_number": ("-", "(T, K) droplets fed since t = 0, per section"),
    "settled_number": ("-", "(T, K) droplets that reached the bottom since t = 0, per section"),
    "lost_number": ("-", "(T, K) droplets that left with the slag since t = 0, per section"),
    "fed_mass": ("kg", "(T, K) matte mass fed since t = 0, per section"),
    "settled_mass": ("kg", "(T, K) matte mass settled since t = 0, per section"),
    "lost_mass": ("kg", "(T, K) matte mass lost with the slag since t = 0, per section"),
    "merges": ("-", "(T, Z, J) coalescence events since t = 0 in each zone's cells (the droplets coalescence removed; "
                    "the roof layer's in its top cell, the bottom layer's in its bottom cell)"),
    "exchanges": ("-", "(T, X) droplets passed since t = 0 along each of the return flow's paths (X: EXCHANGES)"),
}

#: The return flow's paths between zones, in the order of the ``exchanges`` array: name -> meaning. The full runs'
#: counterparts are analysis.circulation's flows between rising slag, sinking slag, the floor and the roof.
EXCHANGES: dict[str, str] = {
    "floor_to_outer": "lifted off the bottom layer into the outer zone (bottom_lift_share)",
    "channel_to_outer": "turned from the channel's bottom outflow into the outer zone (the return flow's turning)",
    "outer_to_channel": "entrained from the outer zone into the channel (entrainment_length)",
    "outer_to_top": "risen out of the outer zone's top cell into the roof layer (or the channel's top cell)",
}
_PATH = {name: index for index, name in enumerate(EXCHANGES)}  # a path's index in the exchanges array


#: Seconds of wall time after which a run started with progress=None begins to report.
AUTO_PROGRESS_AFTER = 5.0


@dataclass
class Result:
    """A finished reduced-model run. Arrays as in :data:`DISTRIBUTION_ARRAYS`; ``timeseries`` a DataFrame with the
    columns of settler.output.TIME_SERIES."""

    model: Model
    timeseries: pd.DataFrame
    arrays: dict[str, np.ndarray]
    wall_time: float
    steps: int
    coalescence_substeps: int = 0
    numbers: list = field(default_factory=list)
    channel_profile: pd.DataFrame = field(default_factory=lambda: pd.DataFrame(columns=list(CHANNEL_PROFILE)))

    def __getattr__(self, name):
        arrays = self.__dict__.get("arrays", {})
        if name in arrays:
            return arrays[name]
        raise AttributeError(name)

    @property
    def case(self) -> Case:
        return self.model.case

    def size_distribution(self, time: float | None = None) -> pd.DataFrame:
        """Long table (zone, z, original_diameter, diameter, number_density, mean_age) at the output nearest ``time``
        (default: the last)."""
        t = self.arrays["time"]
        n = len(t) - 1 if time is None else int(np.argmin(np.abs(t - time)))
        zone, j, k = np.meshgrid(np.arange(len(ZONES)), np.arange(self.model.cells), np.arange(self.model.grid.size),
                                 indexing="ij")
        return pd.DataFrame({
            "time": t[n], "zone": np.array(ZONES)[zone.ravel()], "z": self.arrays["z"][j.ravel()],
            "original_diameter": self.arrays["original_diameter"][k.ravel()],
            "diameter": self.arrays["diameter"][n].ravel(), "number_density": self.arrays["number_density"][n].ravel(),
            "mean_age": self.arrays["mean_age"][n].ravel()})

    def loss_by_size(self) -> pd.DataFrame:
        """Per section at the last output: fed, settled and lost mass and the lost / fed fraction (NaN where none
        was fed). Without coalescence this is the loss fraction vs droplet size."""
        fed, lost, settled = (self.arrays[k][-1] for k in ("fed_mass", "lost_mass", "settled_mass"))
        with np.errstate(invalid="ignore", divide="ignore"):
            fraction = np.where(fed > 0.0, lost / fed, np.nan)
        return pd.DataFrame({"original_diameter": self.arrays["original_diameter"], "fed_mass": fed,
                             "settled_mass": settled, "lost_mass": lost, "loss_fraction": fraction})

    def zone_exchange(self, start: float, end: float) -> dict[str, float]:
        """The return flow's exchanges over the outputs in [start, end] [s]: droplets per second along each path of
        :data:`EXCHANGES`, ``outer_merged`` (coalescence events in the outer zone per second), ``outer_count`` (the
        outer zone's droplets, mean over the outputs) and ``outer_residence`` [s] (that count over the rate at which
        droplets enter it from the floor and the channel; at steady state the rate at which they leave). NaN without
        the arrays or with fewer than two outputs in the window."""
        t = self.arrays["time"]
        inside = np.flatnonzero((t >= start - 1e-9) & (t <= end + 1e-9))
        if "exchanges" not in self.arrays or inside.size < 2:
            return {name: math.nan for name in (*EXCHANGES, "outer_merged", "outer_count", "outer_residence")}
        first, last = inside[0], inside[-1]
        span = t[last] - t[first]
        rates = (self.arrays["exchanges"][last] - self.arrays["exchanges"][first]) / span
        out = dict(zip(EXCHANGES, map(float, rates)))
        merges = self.arrays["merges"][:, OUTER].sum(axis=1)
        out["outer_merged"] = float(merges[last] - merges[first]) / float(span)
        volume = self.arrays["zone_area"][OUTER] * self.model.cell_height
        counts = self.arrays["number_density"][inside, OUTER].sum(axis=(1, 2)) * volume
        out["outer_count"] = float(counts.mean())
        inflow = out["floor_to_outer"] + out["channel_to_outer"]
        out["outer_residence"] = out["outer_count"] / inflow if inflow > 0.0 else math.nan
        return out

    def merges_by_height(self) -> pd.DataFrame:
        """The coalescence events since t = 0 at every output in the height bands of
        :data:`settler.output.MERGES_BY_HEIGHT`, as the full engine counts them: "under the inlet" the roof layer
        and the channel zone, "elsewhere" the outer zone and the bottom layer (the channel is the plume's
        cross-section, R_c, not the inlet's disk; the bottom layer spans the floor). Empty without the ``merges``
        array."""
        if "merges" not in self.arrays:
            return pd.DataFrame(columns=list(MERGES_BY_HEIGHT))
        merges, z = self.arrays["merges"], self.arrays["z"]
        under = merges[:, ROOF] + merges[:, CHANNEL]
        elsewhere = merges[:, OUTER] + merges[:, BOTTOM]
        bands = band_cells(z, self.case.geometry.height)
        rows = [{"time": t, "z": centre, "merges_under_inlet": float(under[n, cells].sum()),
                 "merges_elsewhere": float(elsewhere[n, cells].sum())}
                for n, t in enumerate(self.arrays["time"]) for centre, cells in bands]
        return pd.DataFrame(rows, columns=list(MERGES_BY_HEIGHT))

    def save(self, out_dir: str | os.PathLike, distribution: bool = True) -> Path:
        """Write timeseries.csv, channel_profile.csv, merges_by_height.csv, distribution.npz, case.toml and
        metadata.json into out_dir (atomically).

        distribution=False leaves out distribution.npz (and its entry in metadata.json), deleting one an earlier
        run left in out_dir: a sweep's points need only the time series, and compressing the (T, Z, J, K) arrays
        (6 MB for a furnace run at the preset's resolution) takes 0.5 s, a third of that run's time.
        """
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        write_time_series(self.timeseries, out / "timeseries.csv")
        write_channel_profile(self.channel_profile.to_dict("records"), out / "channel_profile.csv")
        write_table(self.merges_by_height().to_dict("records"), MERGES_BY_HEIGHT, out / "merges_by_height.csv")
        extra = {}
        if distribution:
            buffer = io.BytesIO()
            np.savez_compressed(buffer, **self.arrays)
            atomic_write_bytes(out / "distribution.npz", buffer.getvalue())
            extra["distribution_arrays"] = {k: {"unit": u, "meaning": m} for k, (u, m) in DISTRIBUTION_ARRAYS.items()}
        else:
            (out / "distribution.npz").unlink(missing_ok=True)
        write_run_metadata(out, self.case, "popbal", wall_time=self.wall_time, steps=self.steps, **extra,
                           zones=list(ZONES),
                           start_up={q.name: {"value": q.value, "unit": q.unit, "note": q.note} for q in self.numbers})
        return out


class _Work:
    """Per-zone property arrays and coalescence work space, allocated once per run."""

    def __init__(self, cells: int, sections: int):
        shape = (len(ZONES), cells, sections)
        self.diameters = np.zeros(shape)
        self.densities = np.zeros(shape)
        self.velocities = np.zeros(shape)
        self.volume_fraction = np.zeros((len(ZONES), cells))
        self.collective = np.zeros((len(ZONES), cells))
        self.shear = np.zeros((len(ZONES), cells))
        self.no_cloud = np.zeros(cells)  # the outer zone's cloud coefficient and radius: no collective velocity
        self.beta = np.zeros((sections, sections))
        self.births = np.zeros((QUANTITIES + 1, sections))
        self.k1 = np.zeros((QUANTITIES, sections))
        self.k2 = np.zeros((QUANTITIES, sections))
        self.trial = np.zeros((QUANTITIES, sections))
        self.top_source = np.zeros((QUANTITIES, sections))
        self.bottom_out = np.zeros((QUANTITIES, sections))
        self.sink_out = np.zeros((QUANTITIES, sections))
        # the return flow (model.return_velocity > 0): the channel's bottom outflow turning into the outer zone, what
        # rises out of the outer zone's top, and the tridiagonal solver's rows
        self.turned = np.zeros((QUANTITIES, sections))
        self.top_out = np.zeros((QUANTITIES, sections))
        self.rows = np.zeros((3, cells))
        self.lateral_out = np.zeros((cells, QUANTITIES, sections))  # entrained out of the outer zone [per m^3]
        self.no_loss = np.zeros(cells)
        self.no_source = np.zeros((QUANTITIES, sections))
        self.into_bottom = np.zeros((QUANTITIES, sections))  # what reached the bottom layer in the step [absolute]
        self.roof_out = np.zeros((QUANTITIES, sections))  # what drained from the roof layer during the step [absolute]
        self.roof_in = np.zeros((QUANTITIES, sections))  # the roof layer's inflow during the step [per m^3 per s]


def _properties(model: Model, content: np.ndarray, work: _Work, zone: int):
    p = model.parameters
    coefficient, radius = {CHANNEL: (model.cloud_coefficient, model.cloud_radius),
                           ROOF: (model.roof_coefficient, model.roof_radius)}.get(zone, (work.no_cloud, work.no_cloud))
    cell_properties(content[zone], model.grid.pivots, model.grid.diameters, model.reacting, model.x_initial,
                    model.x_final, model.time_constant, model.velocity_table, model.age_step,
                    p["hindered_exponent"], model.feed_density, p["density_slag"], model.viscosity, model.gravity,
                    coefficient, radius, model.downflow, work.diameters[zone], work.densities[zone],
                    work.velocities[zone], work.volume_fraction[zone], work.collective[zone])
    if zone == OUTER and model.return_upflow.size:  # the slag rises at u_up s(z) outside the plume
        work.velocities[zone] -= model.return_upflow[:, None]
    elif zone == OUTER and model.return_velocity > 0.0:
        work.velocities[zone] -= model.return_velocity  # the slag rises at u_up outside the plume
    if zone == ROOF:  # the slag feed flows through the roof at its inlet velocity, not spread over the box
        work.velocities[zone, -1] += model.roof_slag_velocity - model.downflow[-1]
    if zone == BOTTOM:  # the plume turns over the layer's thickness: G = bottom_shear_coefficient u_s t / h_b
        work.shear[zone] = 0.0
        work.shear[zone, 0] = p["bottom_shear_coefficient"] * model.bottom_turning_rate
        # the plume's discharge drives the layer's droplets into the floor (bottom_drain_coefficient; 0: none)
        work.velocities[zone, 0] += p["bottom_push"]
    elif zone != OUTER and model.channel_radius > 0.0:
        # G = shear_coefficient u / R with the cell's cloud scale (R_c in the plume, delta in the roof layer, which
        # has its own coefficient: roof_shear_coefficient, the channel's where absent)
        coefficient = p["roof_shear_coefficient"] if zone == ROOF else p["shear_coefficient"]
        work.shear[zone] = 0.0
        np.divide(coefficient * work.collective[zone], radius, out=work.shear[zone], where=radius > 0.0)
    else:
        work.shear[zone] = 0.0


class _Books:
    """Cumulative amounts per section [absolute: droplets, m^3 x droplets, kg], reacted FeS [kg] and coalescence
    events per zone and cell [-] (``merges``; ``merges_reported``: their total at the last time-series row)."""

    def __init__(self, sections: int, cells: int = 1):
        self.fed = np.zeros((QUANTITIES, sections))
        self.settled = np.zeros((QUANTITIES, sections))
        self.lost = np.zeros((QUANTITIES, sections))
        self.reacted = 0.0
        self.merges = np.zeros((len(ZONES), cells))
        self.merges_reported = 0.0
        self.exchanges = np.zeros(len(EXCHANGES))  # droplets along each path of EXCHANGES


def _mass(model: Model, amounts: np.ndarray) -> np.ndarray:
    """Matte mass per section [kg] of amounts (Q, K) (or (..., Q, K)): rho_0 x_k N - FeS removed."""
    return model.feed_density * model.grid.pivots * amounts[..., NUMBER, :] - amounts[..., FES_REMOVED, :]


def _channel(model: Model, content: np.ndarray, work: _Work, cells: np.ndarray):
    """(channel radius [m], downward slag velocity on the axis [m/s], droplet volume [m^3]) of the given cells, as
    settler.output defines them for both engines. The zones are uniform: the channel a disk of radius R_c, the outer
    zone the rest of the cross-section, taken as an annulus out to the radius of a disk of the same area; the
    half-volume radius follows in closed form. The velocity is the slag's on the axis: axis_velocity_ratio x the
    channel zone's plume velocity, plus the downflow, averaged over the cells (popbal.closures)."""
    if cells.size == 0:
        return math.nan, math.nan, 0.0
    d = work.diameters[:, cells, :]
    per_zone = (content[:, cells, NUMBER, :] * math.pi / 6.0 * d**3).sum(axis=(1, 2)) \
        * model.zone_area * model.cell_height
    total = float(per_zone.sum())  # with the roof layer's droplets, which the radius below leaves out
    per_zone = per_zone[:ROOF]
    r_c = model.channel_radius
    r_out = math.sqrt(float(model.zone_area[:ROOF].sum()) / math.pi)
    if total <= 0.0:
        radius = math.nan
    elif per_zone[CHANNEL] >= 0.5 * per_zone.sum():
        radius = r_c * math.sqrt(0.5 * per_zone.sum() / per_zone[CHANNEL])
    else:
        radius = math.sqrt(r_c**2 + (0.5 * per_zone.sum() - per_zone[CHANNEL]) / per_zone[OUTER] * (r_out**2 - r_c**2))
    velocity = float(np.mean(model.parameters["axis_velocity_ratio"] * work.collective[CHANNEL, cells]
                             + model.downflow[cells]))
    return radius, velocity, total


def _channel_profile(model: Model, content: np.ndarray, work: _Work, t: float) -> list[dict]:
    """Rows of settler.output.CHANNEL_PROFILE: the channel measures in PROFILE_BANDS height bands."""
    rows = []
    for centre, cells in band_cells(model.z, model.case.geometry.height):
        radius, velocity, volume = _channel(model, content, work, cells)
        rows.append({"time": t, "z": centre, "channel_radius": radius, "channel_velocity": velocity,
                     "droplet_volume": volume})
    return rows


def band_cells(z: np.ndarray, height: float) -> list[tuple[float, np.ndarray]]:
    """(band centre [m], indices of the cells whose centres ``z`` [m] lie in it) for each height band of
    settler.output.band_edges: the bands of the channel profile and of merges_by_height.csv."""
    edges = band_edges(height)
    return [(0.5 * (low + high), np.flatnonzero((z >= low) & (z < high))) for low, high in zip(edges[:-1], edges[1:])]


def _snapshot(model: Model, content: np.ndarray, work: _Work, books: _Books, t: float):
    """A time-series row and the distribution arrays at time t (properties must be current)."""
    volume = model.zone_area[:, None] * model.cell_height  # (Z, 1) cell volume per zone
    number = content[:, :, NUMBER, :]  # (Z, J, K)
    weights = number * volume[:, :, None]
    count = weights.sum()
    d = work.diameters
    in_slag = float((_mass(model, content) * volume[:, :, None]).sum())
    row = {"time": t, "droplet_count": count, "mass_in_slag": in_slag}
    if count > 0.0:
        row["mean_diameter"] = (weights * d).sum() / count
        row["sauter_diameter"] = (weights * d**3).sum() / (weights * d**2).sum()
        row["mean_settling_velocity"] = (weights * work.velocities).sum() / count
    # centreline: droplets within one inlet radius of the axis, in the cell(s) at mid-height
    height = model.case.geometry.height
    mid = np.flatnonzero(np.abs(model.z - 0.5 * height) <= 0.5 * model.cell_height + 1e-12 * height)
    inside = math.pi * min(model.channel_radius, model.inlet_radius) ** 2
    area_in = np.array([inside, max(math.pi * model.inlet_radius**2 - inside, 0.0)])
    w_mid = number[:ROOF][:, mid, :] * area_in[:, None, None]
    if w_mid.sum() > 0.0:
        row["centreline_settling_velocity"] = (w_mid * work.velocities[:ROOF][:, mid, :]).sum() / w_mid.sum()
    band = np.flatnonzero(np.abs(model.z - 0.5 * height) <= MID_BAND * height + 1e-12 * height)
    band = band if band.size else mid  # cells taller than the band: the mid-height cell(s)
    row["channel_radius"], row["channel_velocity"], _ = _channel(model, content, work, band)
    fed = float(_mass(model, books.fed).sum())
    settled = float(_mass(model, books.settled).sum())
    lost = float(_mass(model, books.lost).sum())
    row.update(mass_fed=fed, mass_settled=settled, mass_lost=lost, mass_reacted=books.reacted,
               mass_balance_error=(fed - in_slag - settled - lost - books.reacted) / max(fed, 1e-300))
    merged = float(books.merges.sum())
    row["merges"] = merged - books.merges_reported
    books.merges_reported = merged
    with np.errstate(invalid="ignore", divide="ignore"):
        occupied = number > 0.0
        mean_age = np.where(occupied, content[:, :, AGE, :] / (number * model.grid.pivots), np.nan)
        diameter = np.where(occupied, d, np.nan)
    arrays = {"number_density": number.copy(), "diameter": diameter, "mean_age": mean_age,
              "fed_number": books.fed[NUMBER].copy(), "settled_number": books.settled[NUMBER].copy(),
              "lost_number": books.lost[NUMBER].copy(), "fed_mass": _mass(model, books.fed),
              "settled_mass": _mass(model, books.settled), "lost_mass": _mass(model, books.lost),
              "merges": books.merges.copy(), "exchanges": books.exchanges.copy()}
    return row, arrays


def _step(model: Model, content: np.ndarray, work: _Work, books: _Books, zones: list[int], dt: float,
          feeding: bool) -> int:
    """One split step of length dt in every zone: transport with feed, sink and settling; coalescence; reaction.

    Properties in ``work`` are those of the step start. Books every amount that enters or leaves. Returns the
    largest number of coalescence sub-steps any cell needed.
    """
    p, grid, dz = model.parameters, model.grid, model.cell_height
    most = 0
    for zone in zones:
        area = model.zone_area[zone]
        work.top_source[:] = 0.0
        if feeding and (zone == OUTER or (zone == CHANNEL and not model.roof)):  # a roof takes the channel's feed
            rate = model.feed_multiplier * model.zone_feed_fraction[zone] * model.feed_number_rate
            work.top_source[NUMBER] = rate / (area * dz)
            books.fed[NUMBER] += dt * rate
        if zone == CHANNEL and model.roof:
            work.top_source += work.roof_out / (area * dz * dt)
        work.bottom_out[:] = 0.0
        work.sink_out[:] = 0.0
        if zone == ROOF:
            _roof_zone(model, content, work, books, dt, feeding)
        elif zone == BOTTOM:
            _bottom_zone(model, content, work, books, dt)
        elif model.return_velocity > 0.0 and zone == OUTER:
            _return_zone(model, content, work, books, dt)
        else:
            transport_zone(content[zone], work.velocities[zone], model.sink_rate, work.top_source, dz, dt,
                           work.bottom_out, work.sink_out)
            # the outer zone's droplets' own hindered settling velocity U_h: its velocity in the bottom cell plus
            # the upflow there (u_up, or u_up s(z) with the circulation's profile)
            upflow = model.return_upflow[0] if model.return_upflow.size else model.return_velocity
            if model.return_velocity > 0.0 and not model.bottom:  # the channel: a share settles, the rest turns
                share = settling_share(work.velocities[OUTER, 0] + upflow, model.return_velocity)
                work.turned[:] = work.bottom_out * (1.0 - share)[None, :] * area
                work.bottom_out *= share[None, :]
                books.exchanges[_PATH["channel_to_outer"]] += work.turned[NUMBER].sum()
            elif p["bottom_turning"] > 0.0 and zone == CHANNEL:  # a share of the slow ones turns, the rest goes down
                turning = turning_share(p["bottom_turning"], work.velocities[OUTER, 0] + upflow,
                                        model.return_velocity, p["bottom_turning_uniform"])
                work.turned[:] = work.bottom_out * turning[None, :] * area
                work.bottom_out *= (1.0 - turning)[None, :]
                books.exchanges[_PATH["channel_to_outer"]] += work.turned[NUMBER].sum()
            _reach_floor(model, work, books, area)
        books.lost += work.sink_out * area
        if p["coalescence"]:
            efficiency = p["roof_efficiency"] if zone == ROOF else \
                p["channel_efficiency"] if zone == CHANNEL else p["efficiency"]
            before = content[zone, :, NUMBER, :].sum(axis=1)
            most = max(most, coalesce_zone(
                content[zone], work.diameters[zone], work.velocities[zone], work.densities[zone],
                work.volume_fraction[zone], work.shear[zone], grid.pivots, grid.target, grid.loss_weight, dt,
                p["density_slag"], p["interfacial_tension"], p["psi"], p["virtual_mass"], p["form"],
                p["threshold"], p["rule"], efficiency, p["speed_limit"], p["max_rate_step"], work.beta,
                work.births, work.k1, work.k2, work.trial, p["busy_partners"], p["growth_target"], p["growth_rate"]))
            # each binary event removes one droplet (the cell-average technique keeps number and volume of births)
            books.merges[zone] += (before - content[zone, :, NUMBER, :].sum(axis=1)) * area * dz
        removed = react_zone(content[zone], grid.pivots, grid.diameters, model.reacting, model.x_initial,
                             model.x_final, model.time_constant, dt)
        books.reacted += removed * dz * area
    return most


def _return_zone(model: Model, content: np.ndarray, work: _Work, books: _Books, dt: float) -> None:
    """Transport in the outer zone with the return flow: velocities of either sign, the channel's turned outflow
    entering its bottom cell, what rises out of its top put into the channel's top cell; with the circulation's
    profile the turned outflow enters where the plume gives its slag back and what the plume entrains goes into the
    channel's cell at its height (popbal.closures)."""
    area, dz = model.zone_area[OUTER], model.cell_height
    work.top_out[:] = 0.0
    entraining = model.exchange_rate.size > 0
    if entraining:  # the channel's turned outflow comes with the slag the plume gives back, where it gives it
        content[OUTER] += work.turned[None] * (model.turning_weight[:, None, None] / (area * dz))
        bottom_source = work.no_source
    else:  # into the bottom cell (the channel's step ran first) [1/m^3/s]
        bottom_source = work.turned / (area * dz * dt)
    work.lateral_out[:] = 0.0
    transport_two_way(content[OUTER], work.velocities[OUTER], model.sink_rate, work.top_source, bottom_source, dz, dt,
                      work.bottom_out, work.top_out, work.sink_out, work.rows[0], work.rows[1], work.rows[2],
                      model.exchange_rate if entraining else work.no_loss, work.lateral_out,
                      model.parameters["outer_dispersion"])
    if entraining:  # the plume takes the entrained droplets into the channel's cell at their height
        content[CHANNEL] += work.lateral_out * (area / model.zone_area[CHANNEL])
        books.exchanges[_PATH["outer_to_channel"]] += work.lateral_out[:, NUMBER].sum() * area * dz
    books.exchanges[_PATH["outer_to_top"]] += work.top_out[NUMBER].sum() * area
    _reach_floor(model, work, books, area)
    rise_into = ROOF if model.roof else CHANNEL  # the risers rejoin the roof layer where there is one
    content[rise_into, -1] += work.top_out * area / (model.zone_area[rise_into] * dz)
    work.turned[:] = 0.0


def _reach_floor(model: Model, work: _Work, books: _Books, area: float) -> None:
    """What left a zone (of ``area`` [m^2]) through its bottom this step, work.bottom_out [per m^2]: settled, or into
    the bottom layer where there is one, which drops it on the floor (:func:`_bottom_zone`)."""
    if model.bottom:
        work.into_bottom += work.bottom_out * area
    else:
        books.settled += work.bottom_out * area


def _layer_step(content: np.ndarray, inflow: np.ndarray, velocity: np.ndarray, thickness: float, dt: float
                ) -> np.ndarray:
    """One well-mixed layer's cell over dt: dc/dt = inflow - (v / h) c per section, integrated exactly for the
    step's v (so the steady state c = inflow h / v holds whatever dt). content (Q, K) [per m^3] is updated in place;
    returns what drained out of it [per m^3]. inflow (Q, K) [per m^3 per s], velocity (K,) [m/s, >= 0]."""
    rate = velocity / thickness
    decay = np.exp(-dt * rate)
    with np.errstate(invalid="ignore", divide="ignore"):
        gained = np.where(rate > 0.0, -np.expm1(-dt * rate) / rate, dt)  # integral of exp(-rate s) over the step
    new = content * decay[None, :] + inflow * gained[None, :]
    out = content + inflow * dt - new
    content[:] = new
    return out


def _bottom_zone(model: Model, content: np.ndarray, work: _Work, books: _Books, dt: float) -> None:
    """The bottom layer over dt (popbal.closures): what left the channel's and the outer zone's bottom during the
    step flows into its one (bottom) cell at a constant rate, and section k drops onto the floor (settles) at its
    own hindered settling velocity v_k (properties at the step start): :func:`_layer_step`. With
    ``bottom_lift_share`` a share of what leaves goes up into the outer zone's bottom cell instead
    (:func:`popbal.closures.lift_share`)."""
    volume = model.zone_area[BOTTOM] * model.cell_height
    velocity = np.maximum(work.velocities[BOTTOM, 0], 0.0)
    out = _layer_step(content[BOTTOM, 0], work.into_bottom / (volume * dt), velocity, model.bottom_thickness, dt)
    work.into_bottom[:] = 0.0
    p = model.parameters
    if p["bottom_lift"] > 0.0:  # the return flow carries a share of the slow droplets off the floor, by size
        own = velocity - p["bottom_push"]  # their own hindered settling, without the plume's push
        lifted = out * lift_share(own, p["bottom_lift"], p["bottom_lift_velocity"])[None, :]
        content[OUTER, 0] += lifted * volume / (model.zone_area[OUTER] * model.cell_height)
        out = out - lifted
        books.exchanges[_PATH["floor_to_outer"]] += lifted[NUMBER].sum() * volume
    books.settled += out * volume


def _roof_zone(model: Model, content: np.ndarray, work: _Work, books: _Books, dt: float, feeding: bool) -> None:
    """The roof layer over dt (popbal.closures): the channel's share of the feed enters its one (top) cell, and
    section k drains out of its bottom at its velocity v_k (the layer's u_L plus the droplets' own hindered
    settling, or u_L plus the slag's w alone with ``roof_drainage = "cloud"``; properties at the step start):
    :func:`_layer_step`. What drained goes to work.roof_out [absolute
    amounts], which the channel's top cell receives in the same step."""
    volume = model.zone_area[ROOF] * model.cell_height
    inflow = work.roof_in
    inflow[:] = 0.0
    if feeding:
        rate = model.feed_multiplier * model.zone_feed_fraction[CHANNEL] * model.feed_number_rate
        inflow[NUMBER] = rate / volume
        books.fed[NUMBER] += dt * rate
    if model.parameters["roof_cloud_drainage"]:  # the layer drains as one cloud at u_L + w, every size alike (its
        # droplets still collide at their own velocities: work.velocities is left as it is)
        velocity = np.full(work.velocities.shape[-1], max(work.collective[ROOF, -1] + model.roof_slag_velocity, 0.0))
    else:
        velocity = np.maximum(work.velocities[ROOF, -1], 0.0)
    work.roof_out[:] = _layer_step(content[ROOF, -1], inflow, velocity, model.roof_thickness, dt) * volume


def _seconds(name: str, value) -> float:
    """A simulated time argument [s]: a finite number > 0, else ValueError naming the argument."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} = {value!r}: not a number; allowed: a finite number of seconds > 0")
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} = {value!r} s: allowed: a finite number of seconds > 0")
    return value


def check_run(model: Model, end_time: float | None = None, output_interval: float | None = None,
              names: tuple[str, str] = ("end_time", "output_interval")) -> tuple[float, float, float]:
    """The stop time, output interval [s] and number of outputs of a run of ``model`` with these arguments (None:
    the case's popbal.end_time / popbal.output_interval).

    Refuses with ValueError an argument that is not a finite number > 0, and with settler.cases.CaseError a run
    whose outputs, time steps or arrays exceed popbal.limits (MAX_OUTPUTS, MAX_STEPS, memory_limit()). ``names``
    name the two arguments in the messages (the command line passes its options, ``--end-time`` and
    ``--output-interval``).
    """
    p = model.case.popbal
    end_name, interval_name = names
    if end_time is None:
        end_name, end_value, stop = "popbal.end_time", p.end_time, model.stop_time
    else:
        end_value = _seconds(end_name, end_time)
        stop = min(end_value, model.residence_time) if model.horizontal else end_value
    if output_interval is None:
        interval_name, interval = "popbal.output_interval", model.parameters["output_interval"]
    else:
        interval = _seconds(interval_name, output_interval)
    outputs = limits.check_outputs(stop, interval, interval_name, end_name, end_value)
    limits.check_steps(stop, model.parameters["time_step"], end_name, end_value)
    limits.check(model.cells, p.sections_per_doubling, model.grid.size, outputs, model.velocity_table.shape[1],
                 model.parameters["speed_limit"].size > 0, interval_name, interval)
    return stop, interval, outputs


def run(model: Model | Case | str, end_time: float | None = None, output_interval: float | None = None,
        progress: bool | None = None, progress_interval: float = 2.0, stream=None, **overrides) -> Result:
    """Run the reduced model and return a :class:`Result`.

    model: a :class:`Model` from :func:`popbal.setup`, a case, or a preset name / path (then ``overrides`` as in
    setup). end_time, output_interval [s] override popbal.end_time / popbal.output_interval: finite numbers > 0
    (else ValueError), and no more outputs or memory than :func:`check_run` allows (else CaseError). progress: True prints
    the start-up numbers and a progress line to ``stream`` (stderr) every progress_interval seconds of wall time;
    False prints nothing; None (default) starts the progress lines once a run has taken AUTO_PROGRESS_AFTER seconds,
    so short runs stay quiet and long ones report.
    """
    if not isinstance(model, Model):
        model = setup(model, **overrides)
    elif overrides:
        raise TypeError("run: overrides apply when a case is given; pass them to popbal.setup for a Model")
    p = model.parameters
    stop, interval, _ = check_run(model, end_time, output_interval)
    automatic = progress is None
    stream = stream or sys.stderr
    grid, cells, dz = model.grid, model.cells, model.cell_height
    content = np.zeros((len(ZONES), cells, QUANTITIES, grid.size))
    work = _Work(cells, grid.size)
    books = _Books(grid.size, cells)
    # the roof drains into the channel, channel and outer zone into the bottom layer
    zones = [z for z in (ROOF, CHANNEL, OUTER, BOTTOM) if model.zone_area[z] > 0.0]
    numbers = model.numbers()
    start_up_line = f"popbal {model.name}: " + "; ".join(f"{q.name} {q.value:.4g} {q.unit}" for q in numbers)
    if progress:
        print(start_up_line, file=stream)

    rows, snapshots, profile = [], [], []
    started = wallclock.perf_counter()
    last_report = started
    t, steps, most_substeps = 0.0, 0, 0
    outputs = np.append(np.arange(0.0, stop, interval), stop)
    outputs = outputs[np.concatenate([[True], np.diff(outputs) > 1e-9 * stop])]
    next_output = 0
    tiny = 1e-12 * stop
    while True:
        for zone in zones:
            _properties(model, content, work, zone)
        if next_output < outputs.size and t >= outputs[next_output] - tiny:
            row, arrays = _snapshot(model, content, work, books, t)
            rows.append(row)
            snapshots.append(arrays)
            profile += _channel_profile(model, content, work, t)
            next_output += 1
        if t >= stop - tiny:
            break
        occupied = content[:, :, NUMBER, :] * grid.pivots >= NEGLIGIBLE_VOLUME_FRACTION
        fastest = np.abs(work.velocities[occupied]).max() if occupied.any() else 0.0
        dt = min(p["time_step"], outputs[next_output] - t)
        if fastest > 0.0:
            dt = min(dt, p["max_courant"] * dz / fastest)
            limits.check_projected_steps(steps, t, stop, min(p["time_step"], p["max_courant"] * dz / fastest), fastest,
                                         p["max_courant"], dz)
        feeding = t < model.feed_end - tiny
        if feeding:
            dt = min(dt, model.feed_end - t)
        most_substeps = max(most_substeps, _step(model, content, work, books, zones, dt, feeding))
        t = outputs[next_output] if abs(outputs[next_output] - (t + dt)) <= tiny else t + dt
        steps += 1
        if model.horizontal and t >= model.residence_time - tiny:
            # the column has reached the tap hole: whatever is still suspended leaves with the slag
            volume = model.zone_area[:, None, None, None] * dz
            books.lost += (content * volume).sum(axis=1).sum(axis=0)
            content[:] = 0.0
        if automatic and wallclock.perf_counter() - started >= AUTO_PROGRESS_AFTER:
            automatic, progress = False, True
            print(start_up_line, file=stream)
        if progress and wallclock.perf_counter() - last_report >= progress_interval:
            last_report = wallclock.perf_counter()
            fed = float(_mass(model, books.fed).sum())
            settled = float(_mass(model, books.settled).sum())
            count = float((content[:, :, NUMBER, :] * (model.zone_area[:, None, None] * dz)).sum())
            print(f"popbal {model.name}: t = {t:.5g} / {stop:.5g} s, {steps} steps, {count:.4g} droplets, "
                  f"settled {100 * settled / max(fed, 1e-300):.3g} % of fed, wall {last_report - started:.1f} s",
                  file=stream, flush=True)
    wall = wallclock.perf_counter() - started
    arrays = {"time": np.array([r["time"] for r in rows]), "z": model.z.copy(), "zone_area": model.zone_area.copy(),
              "original_volume": grid.pivots.copy(), "original_diameter": grid.diameters.copy()}
    for key in snapshots[0]:
        arrays[key] = np.stack([s[key] for s in snapshots])
    if progress:
        print(f"popbal {model.name}: done, {steps} steps in {wall:.2f} s", file=stream, flush=True)
    return Result(model=model, timeseries=time_series_frame(rows), arrays=arrays, wall_time=wall, steps=steps,
                  coalescence_substeps=most_substeps, numbers=numbers,
                  channel_profile=pd.DataFrame(profile, columns=list(CHANNEL_PROFILE)))
