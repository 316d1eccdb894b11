"""Case files: TOML presets validated on load into typed, immutable records.

A case is resolved in layers, later ones winning:

1. the *property set* named by ``case.properties`` (``data/properties/<name>.toml``): slag, matte, feed and model
   constants, each with its source;
2. the *calibration layer* named by ``case.calibration`` (``data/calibration/<name>.toml``, written by ``settler
   calibrate``): popbal's closures fitted to the full engine's reference runs, with their provenance in a
   ``[provenance]`` table that is not merged; ``"none"``: no layer. A layer named by an *override*
   (``case.calibration=NAME`` or ``none``) is applied after the case file instead, so that it replaces the file's
   values of the keys it sets, and the keys the file's own layer sets are dropped from the file first: that is how
   a run's resolved ``case.toml``, which spells out every key, takes another layer or none, with the same result
   as the preset given by name. Values an earlier override baked into a resolved file are replaced too where
   either layer sets the key;
3. the *case file* (``data/cases/<name>.toml`` or any path): geometry, feeds, size limit, submodel switches;
4. *overrides* ``section.key=value`` from the command line or from :func:`load_case`'s ``overrides``.

The schema below is the one place where every key, its type, unit, allowed range and meaning are written; the
README's case-file reference is generated from it (``settler cases --schema``). Values are SI throughout.
Unknown keys, wrong types and out-of-range values raise :class:`CaseError` naming the key, the value and what is
allowed.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

# DATA_DIR: folder of the property sets and case presets: the SETTLER_DATA environment variable, else the checkout's
# data/, else the copy installed with the package (see settler.paths).
from .errors import CaseError
from .paths import DATA_DIR, DATA_DIR_SOURCE, preset_names
# The choices of the interchangeable models come from their registries, so a new model is added in one place.
from .physics import (COALESCENCE_RULES, DRAG_LAWS, HINDRANCE, PROBABILITY_FORMS, cu2s_fraction_from_density,
                      matte_density, slag_viscosity)


@dataclass(frozen=True)
class Field:
    """One key of the schema: its type, unit, allowed values and meaning."""

    kind: type
    unit: str
    doc: str
    minimum: float | None = None
    maximum: float | None = None
    exclusive_minimum: bool = False
    choices: tuple | None = None
    length: int | None = None  # for list-valued keys
    optional: bool = False  # may be absent (value None)

    def allowed(self) -> str:
        if self.choices is not None:
            return "one of " + ", ".join(repr(c) for c in self.choices)
        kind = {float: "a number", int: "an integer", bool: "true or false", str: "a string",
                list: f"a list of {self.length} numbers" if self.length else "a non-empty list of numbers"}[self.kind]
        bounds = []
        if self.minimum is not None:
            bounds.append(("> " if self.exclusive_minimum else ">= ") + f"{self.minimum:g}")
        if self.maximum is not None:
            bounds.append(f"<= {self.maximum:g}")
        return kind + (" " + " and ".join(bounds) if bounds else "")


F, I, B, S, L = float, int, bool, str, list
SCHEMA: dict[str, dict[str, Field]] = {
    "case": {
        "name": Field(S, "", "Short name of the case."),
        "description": Field(S, "", "One line on what the case is."),
        "properties": Field(S, "", "Property set in data/properties/ providing the defaults; without one, the case "
                                  "file must give every key.", optional=True),
        "calibration": Field(S, "", "Calibration layer in data/calibration/ (e.g. 'paper': popbal's closures fitted "
                                    "to the full engine's reference runs by 'settler calibrate'), applied over the "
                                    "property set and under the case file and overrides; named by an override, "
                                    "over the case file; absent or 'none': none.",
                             optional=True),
    },
    "geometry": {
        "height": Field(F, "m", "Slag layer height h (z, gravity along -z).", 0.0, exclusive_minimum=True),
        "width": Field(F, "m", "Box extent along x (a).", 0.0, exclusive_minimum=True),
        "depth": Field(F, "m", "Box extent along y (a).", 0.0, exclusive_minimum=True),
        "inlet_diameter": Field(F, "m", "Diameter of the feed disk on the top surface.", 0.0,
                                exclusive_minimum=True),
        "inlet_center": Field(L, "m", "(x, y) of the inlet centre on the top surface; default the middle.",
                              length=2, optional=True),
        "inlet_length": Field(F, "m", "Length along x of a slot inlet: with it the feed enters over a rectangle "
                              "inlet_length (x) by inlet_diameter (y) centred at inlet_center, matte only "
                              "(slag.feed_rate = 0); absent: a disk of inlet_diameter.", 0.0, exclusive_minimum=True,
                              optional=True),
        "outlet_diameter": Field(F, "m", "Diameter of the side pressure outlet; 0 for none (closed box).", 0.0),
        "outlet_height": Field(F, "m", "Height of the outlet centre above the bottom.", 0.0),
        "outlet_side": Field(S, "", "Wall holding the outlet.", choices=("x-", "x+", "y-", "y+")),
    },
    "slag": {
        "density": Field(F, "kg/m^3", "Slag density.", 0.0, exclusive_minimum=True),
        "viscosity_reference": Field(F, "Pa s", "Slag dynamic viscosity at the reference temperature.", 0.0,
                                     exclusive_minimum=True),
        "reference_temperature": Field(F, "K", "Temperature of viscosity_reference.", 0.0,
                                       exclusive_minimum=True),
        "activation_energy": Field(F, "J/mol", "Arrhenius activation energy of the slag viscosity.", 0.0),
        "temperature": Field(F, "K", "Slag temperature of the run.", 0.0, exclusive_minimum=True),
        "feed_rate": Field(F, "kg/s", "Slag mass fed through the inlet (must leave through the outlet).", 0.0),
    },
    "matte": {
        "density": Field(F, "kg/m^3", "Density of fed matte (with reactions: sets the feed Cu2S fraction by Eq. 4).",
                         0.0, exclusive_minimum=True),
        "viscosity": Field(F, "Pa s", "Matte dynamic viscosity (Hadamard-Rybczynski factor only).", 0.0,
                           exclusive_minimum=True),
        "interfacial_tension": Field(F, "N/m", "Matte-slag interfacial tension sigma (Weber number).", 0.0,
                                     exclusive_minimum=True),
    },
    "feed": {
        "mass_rate": Field(F, "kg/s", "Matte mass fed through the inlet.", 0.0),
        "mean_diameter": Field(F, "m", "Mean fed droplet diameter d_mean.", 0.0, exclusive_minimum=True),
        "scale_std": Field(F, "-", "Standard deviation of the scale factor s ~ Normal(1, std).", 0.0, 1.0),
        "scale_min": Field(F, "-", "Lower truncation of s.", 0.0, 1.0, exclusive_minimum=True),
        "scale_max": Field(F, "-", "Upper truncation of s.", 1.0),
        "seed": Field(I, "-", "Seed of the feed's random numbers (reproducible runs).", 0),
        "distribution": Field(S, "", "Feed size distribution: 'normal' (d_mean x truncated-normal scale factor) or "
                                     "'table' (table_diameters with table_mass_fractions).",
                              choices=("normal", "table")),
        "table_diameters": Field(L, "m", "Fed droplet diameters of the 'table' distribution.", optional=True),
        "table_mass_fractions": Field(L, "-", "Mass fraction of the matte feed at each table diameter (sum 1).",
                                      optional=True),
    },
    "drag": {
        "law": Field(S, "", "Single-droplet drag law.", choices=DRAG_LAWS.names()),
        "fluid_drop": Field(B, "", "Apply the Hadamard-Rybczynski fluid-drop factor (off: rigid spheres, as the "
                                   "seed paper)."),
    },
    "coalescence": {
        "enabled": Field(B, "", "Coalescence submodel on or off."),
        "size_limit": Field(F, "m", "Largest droplet a coalescence may create.", 0.0, exclusive_minimum=True),
        "probability_form": Field(S, "", "Form of Eq. 2: seed paper's or Luo's square root.",
                                  choices=PROBABILITY_FORMS.names()),
        "psi": Field(F, "-", "Order-of-unity constant Psi of Eq. 2.", 0.0),
        "virtual_mass": Field(F, "-", "Virtual-mass coefficient gamma of Eq. 2.", 0.0),
        "threshold": Field(F, "-", "A colliding pair coalesces when P_c >= threshold.", 0.0, 1.0),
        "growth_target": Field(F, "-", "Marked droplets grow until this fraction of the merged size.", 0.0, 1.0,
                               exclusive_minimum=True),
        "growth_rate": Field(F, "1/s", "Growth speed of a marked droplet's contact diameter, in merged diameters per "
                                       "second (full engine; a bracketed choice, the paper gives none: the demo's steady count is 5 % "
                                       "lower at 20 than at 2).", 0.0, exclusive_minimum=True),
        "mode": Field(S, "", "'delayed': marked pairs grow, then merge (seed paper); 'instantaneous': merge at first "
                             "contact (the paper's previous model, section 4.1; full engine).",
                      choices=("delayed", "instantaneous")),
        "trigger": Field(S, "", "Which contacts are evaluated for coalescence: 'every_contact' (every free pair in "
                                "contact at each fluid step, as the seed paper's section 3.3.1; the default) or "
                                "'first_contact' (a pair's first contact only, the engine's rule before; full engine).",
                         choices=("every_contact", "first_contact")),
    },
    "reaction": {
        "enabled": Field(B, "", "Reaction submodel (FeS removal: droplets shrink and densify) on or off."),
        "end_state": Field(S, "", "X_inf of the reaction fit: 'fixed' uses x_final, 'equilibrium' computes it "
                                  "with Cantera (settler.thermo).", choices=("fixed", "equilibrium")),
        "x_final": Field(F, "-", "End-state Cu2S mole fraction X_inf when end_state = 'fixed'.", 0.0, 1.0,
                         exclusive_minimum=True),
        "time_constant": Field(F, "s", "Time constant tau of X(age) = X_inf - (X_inf - X0) exp(-age/tau).", 0.0,
                               exclusive_minimum=True),
        "mode": Field(S, "", "'continuous': every droplet follows the fit's density and size (default); 'stepped': "
                             "the seed paper's EDEM materials, density rounded to steps of density_step (full "
                             "engine).", choices=("continuous", "stepped")),
        "density_step": Field(F, "kg/m^3", "Density step between the materials of mode = 'stepped'.", 0.0,
                              exclusive_minimum=True),
        "oxygen_pressure": Field(F, "Pa", "Oxygen partial pressure for end_state = 'equilibrium'.", 0.0,
                                 exclusive_minimum=True),
        "so2_pressure": Field(F, "Pa", "SO2 partial pressure for end_state = 'equilibrium'.", 0.0,
                              exclusive_minimum=True),
        "feo_activity": Field(F, "-", "FeO activity in the slag for end_state = 'equilibrium'.", 0.0, 1.0,
                              exclusive_minimum=True),
    },
    "fulldem": {
        "cell_size": Field(F, "m", "Fluid grid spacing (cubic cells; must divide the box).", 0.0,
                           exclusive_minimum=True),
        "fluid_step": Field(F, "s", "Fluid (CFD) time step; DEM sub-steps fill it. At most h^2 / (6 nu), the "
                                    "explicit viscous limit (0.0292 s for 5 mm cells in slag of 0.45 Pa s; a quarter "
                                    "of that at 2.5 mm cells, half again at twice the viscosity).", 0.0,
                            exclusive_minimum=True),
        "dem_step": Field(F, "s", "DEM time step; 0 chooses it from the contact time (contact_steps per contact).",
                          0.0),
        "contact_steps": Field(I, "-", "DEM steps per contact duration when dem_step = 0.", 5),
        "max_overlap": Field(F, "-", "Overlap target / smaller diameter that sets the contact stiffness.", 0.0, 0.2,
                             exclusive_minimum=True),
        "load_factor": Field(F, "-", "Buoyant droplet weights one contact must carry at max_overlap.", 0.0,
                             exclusive_minimum=True),
        "restitution": Field(F, "-", "Normal restitution coefficient of droplet contacts (sets the damping).", 0.0,
                             1.0, exclusive_minimum=True),
        "sigma_cells": Field(F, "-", "Smoothing-kernel width in cells (lower bound of sigma).", 0.0,
                             exclusive_minimum=True),
        "sigma_diameter": Field(F, "-", "Smoothing-kernel width in droplet diameters (sigma grows with size).", 0.0),
        "kernel": Field(S, "", "Coupling kernel: 'direct' (a Gaussian stencil per droplet) or 'filtered' "
                        "(trilinear weights, then a Gaussian filter on the grid; same width and variance; about 1.9x "
                        "faster per coupled step at 130 000 droplets). Droplets wider than sigma_cells cells use "
                        "the direct kernel either way.",
                        choices=("filtered", "direct")),
        "near_wall": Field(S, "", "The slag velocity a droplet's drag sees next to a wall: 'interior' (interior "
                           "faces only: within a cell of a wall a droplet reads the wall-normal velocity of the faces "
                           "one and two cells out, never the wall's zero; the engine before 2026-12-05, and the only "
                           "form with kernel = 'direct') or 'wall' (the default: the walls' boundary faces enter "
                           "the filtered kernel's trilinear weights, so the wall-normal velocity a droplet sees "
                           "falls linearly to zero at the wall, and the drag reaction's share on them goes to the "
                           "wall; inlet and outlet faces count as walls; only with kernel = "
                           "'filtered', and droplets wider than sigma_cells cells keep the interior weights).",
                           choices=("interior", "wall")),
        "hindrance": Field(S, "", "Void-fraction correction of the drag.", choices=HINDRANCE.names()),
        "self_correction": Field(B, "", "Remove the droplet's own disturbance from the interpolated velocity."),
        "advection": Field(B, "", "Fluid inertia (advection) on; off gives unsteady Stokes flow."),
        "end_time": Field(F, "s", "Simulated time at which the run stops.", 0.0, exclusive_minimum=True),
        "output_interval": Field(F, "s", "Simulated time between time-series rows.", 0.0, exclusive_minimum=True),
        "snapshot_interval": Field(F, "s", "Simulated time between ParaView snapshots; 0 for none.", 0.0),
        "checkpoint_interval": Field(F, "s", "Wall-clock time between checkpoints.", 0.0, exclusive_minimum=True),
        "insertion_layer": Field(F, "m", "Thickness of the layer under the inlet where droplets are inserted.", 0.0),
        "insertion_tries": Field(I, "-", "Random positions tried per fed droplet before it waits a step.", 1),
        "overlap_abort": Field(F, "-", "Overlap / smaller diameter beyond which the run stops (blow-up).", 0.0,
                               exclusive_minimum=True),
    },
    "popbal": {
        "slag_flow": Field(S, "", "Slag flow of the reduced model: 'vertical' (slag fed at the top leaves by the side "
                                  "outlet: downflow and a sink in the outlet band) or 'horizontal' (the column rides "
                                  "the settler's plug flow; what is suspended after the residence time is lost).",
                           choices=("vertical", "horizontal")),
        "end_time": Field(F, "s", "Simulated time at which the run stops (horizontal: at most the residence time).",
                          0.0, exclusive_minimum=True),
        "output_interval": Field(F, "s", "Simulated time between time-series rows and distribution snapshots.", 0.0,
                                 exclusive_minimum=True),
        "height_cells": Field(I, "-", "Finite-volume cells over the slag height.", 4),
        "sections_per_doubling": Field(I, "-", "Sections per doubling of droplet volume (pivot ratio 2^(1/n)).", 1),
        "time_step": Field(F, "s", "Largest time step.", 0.0, exclusive_minimum=True),
        "max_courant": Field(F, "-", "Largest Courant number u dt/dz of any occupied section (implicit transport, so "
                                     "it bounds accuracy, not stability).", 0.0, exclusive_minimum=True),
        "hindered_exponent": Field(F, "-", "Richardson-Zaki exponent n of the hindered-settling factor (0: none).",
                                   0.0),
        "coalescence_rule": Field(S, "", "How P_c makes a collision a merger: 'step' (P_c >= coalescence.threshold, "
                                         "the DEM rule) or 'probability' (with probability P_c).",
                                  choices=COALESCENCE_RULES.names()),
        "collision_efficiency": Field(F, "-", "Collision efficiency multiplying the collision frequency.", 0.0),
        "shear_coefficient": Field(F, "-", "Channel shear rate G in units of u_c / R_c (0: no shear collisions).",
                                   0.0),
        "channel_coefficient": Field(F, "-", "c_ch of the plume velocity u_c = c_ch phi drho g R_c^2 / mu (4/15: "
                                             "Hadamard-Rybczynski cloud).", 0.0),
        "channel_feed_fraction": Field(F, "-", "Fraction of the matte feed that enters the channel.", 0.0, 1.0),
        "channel_radius_factor": Field(F, "-", "Channel radius R_c in inlet radii (0: no channel zone).", 0.0),
        "feed_duration": Field(F, "s", "Matte feed stops after this time; absent: feeds for the whole run.", 0.0,
                               exclusive_minimum=True, optional=True),
        "feed_layer_thickness": Field(F, "m", "Thickness delta of the feed layer at the top of the channel zone, where "
                                              "fed droplets collect before the plume takes them (popbal.closures); "
                                              "absent or 0: none (fed droplets enter the plume at once).", 0.0,
                                      optional=True),
        "feed_layer_coefficient": Field(F, "-", "c_L of the feed layer's velocity u_L = c_L phi drho g delta^2 / mu "
                                                "(needed when feed_layer_thickness > 0).", 0.0, optional=True),
        "roof_layer_coefficient": Field(F, "-", "c_L of the roof layer: a well-mixed layer of thickness "
                                                "roof_thickness under the whole inlet disk that takes the channel's "
                                                "feed and the return flow's risers and drains into the channel at "
                                                "u_L = c_L phi drho g delta^2 / mu plus the slag feed's velocity "
                                                "through the inlet disk, so without slag feed it holds sqrt(j mu / "
                                                "(c_L drho g)) of matte per unit area at a feed flux j "
                                                "(popbal.closures); absent: no roof layer.", 0.0,
                                        exclusive_minimum=True, optional=True),
        "roof_thickness": Field(F, "m", "Thickness delta of the roof layer (needed with roof_layer_coefficient and "
                                        "roof_thickness_form 'fixed').", 0.0, exclusive_minimum=True, optional=True),
        "roof_thickness_form": Field(S, "", "How the roof layer's thickness is set (popbal.closures): 'fixed' "
                                            "(popbal.roof_thickness) or 'drainage' (the layer's droplets leave it at "
                                            "roof_drainage_ratio times the Stokes velocity U_s of the mean fed "
                                            "droplet, so it holds the volume fraction j / (k U_s) and is "
                                            "sqrt(mu k U_s (k U_s - w) / (c_L drho g j)) thick, w the slag's velocity "
                                            "through the inlet); absent: 'fixed'.",
                                     choices=("fixed", "drainage"), optional=True),
        "roof_drainage": Field(S, "", "How the roof layer's droplets leave it (popbal.closures): 'sizes' (each "
                                      "section at the layer's cloud velocity u_L plus its own hindered settling) or "
                                      "'cloud' (every section at u_L plus the slag's velocity through the layer, as "
                                      "the roof law j = phi (u_L + w) and its measured c_L and k take it); absent: "
                                      "'sizes'.", choices=("sizes", "cloud"), optional=True),
        "roof_drainage_ratio": Field(F, "-", "k of roof_thickness_form = 'drainage': the roof layer's drainage "
                                             "velocity over U_s, 2.3-2.8 in the resolved reference runs "
                                             "(docs/guide/reduced-model.md).", 0.0, exclusive_minimum=True,
                                     optional=True),
        "bottom_layer_factor": Field(F, "-", "The bottom layer: a well-mixed layer over the whole floor, of thickness "
                                             "h_b = bottom_layer_factor x the channel radius R_c (the plume's "
                                             "discharge spreads about one plume radius deep), that takes what leaves "
                                             "the channel's and the outer zone's bottom and drops it on the floor at "
                                             "the droplets' own hindered settling velocity, merging them at its own "
                                             "volume fraction; none of it turns into the return flow "
                                             "(popbal.closures); absent: no bottom layer.", 0.0,
                                     exclusive_minimum=True, optional=True),
        "plume_core_radius": Field(F, "m", "R_s, the radius of the plume's slag core, with confinement: the "
                                           "confined plume's coefficient c(R / R_s) and return share S(R / R_s) take "
                                           "it in place of the channel radius R_c, which stays the radius of the "
                                           "droplets' channel (their collisions and load) and is no wider than R_s: "
                                           "in the Stokes plumes of the reference runs the droplets fall in a thread "
                                           "narrower than the slag they drive (popbal.closures); absent: R_s = R_c.",
                                   0.0, exclusive_minimum=True, optional=True),
        "plume_core_column_share": Field(F, "-", "beta: with plume_core_radius, the slag core is no wider than beta "
                                                 "times the column's equivalent radius R = sqrt(W D / pi), where a "
                                                 "narrow column leaves the return flow too little room "
                                                 "(popbal.closures); absent: no such bound.", 0.0,
                                         exclusive_minimum=True, optional=True),
        "spread_flux_reynolds": Field(F, "-", "Re_Q,c: with plume_core_radius, a plume whose feed Reynolds number "
                                              "rho_s Q / (mu L) reaches it spreads (L: spread_reference_radius, "
                                              "else plume_core_radius), its slag core then "
                                              "spread_core_share times the column's equivalent radius "
                                              "(popbal.closures); absent: every plume is compact.", 0.0,
                                      exclusive_minimum=True, optional=True),
        "spread_reference_radius": Field(F, "m", "With spread_flux_reynolds: the length at which the regime's feed "
                                                 "Reynolds number rho_s Q / (mu L) is taken, so that a fit of "
                                                 "plume_core_radius does not move runs across the boundary "
                                                 "(popbal.closures), and that of plume_core_exponent's law; absent: "
                                                 "plume_core_radius.", 0.0,
                                         exclusive_minimum=True, optional=True),
        "plume_core_exponent": Field(F, "-", "n: with plume_core_radius and spread_reference_radius L, the compact "
                                             "plume's slag core grows with its feed Reynolds number, R_s = "
                                             "plume_core_radius (Re_Q / plume_core_reynolds)^n, Re_Q = rho_s Q / "
                                             "(mu L): the droplets' half-volume radius of the reference runs grows "
                                             "with it (popbal.closures; L needs the spread rule's keys too); "
                                             "absent: one R_s for every compact plume.",
                                     -2.0, 2.0, optional=True),
        "plume_core_reynolds": Field(F, "-", "Re_Q,0: the feed Reynolds number at which the compact core is "
                                             "plume_core_radius (needed with plume_core_exponent).", 0.0,
                                     exclusive_minimum=True, optional=True),
        "plume_fill_inlet_share": Field(F, "-", "phi_in: with plume_core_column_share beta, a compact plume whose "
                                                "inlet radius reaches phi_in times the column's equivalent radius R "
                                                "fills the column, its slag core beta R: the feed enters over "
                                                "nearly the whole cross-section and leaves the return flow no room "
                                                "to neck it (popbal.closures); absent: no such rule.", 0.0, 1.0,
                                        exclusive_minimum=True, optional=True),
        "spread_core_share": Field(F, "-", "s: the spread plume's slag core over the column's equivalent radius "
                                           "(needed with spread_flux_reynolds).", 0.0, exclusive_minimum=True,
                                   optional=True),
        "roof_collision_efficiency": Field(F, "-", "Collision efficiency of the roof layer: its merges over the "
                                                   "collisions of its droplets well mixed over the layer, i.e. the "
                                                   "engine's local efficiency times how the droplets cluster inside "
                                                   "the layer (popbal.closures); absent: collision_efficiency.", 0.0,
                                           optional=True),
        "channel_collision_efficiency": Field(F, "-", "Collision efficiency of the plume channel below the roof: its "
                                                      "merges over the collisions of its droplets well mixed over the "
                                                      "channel's section pi R_c^2, i.e. the engine's local efficiency "
                                                      "times how compact the plume keeps its droplets within R_c "
                                                      "(popbal.closures; measured by analysis.calibration.hierarchy."
                                                      "channel_kernel_from_collisions); absent: "
                                                      "collision_efficiency.", 0.0, optional=True),
        "channel_collision_radius": Field(F, "m", "b: the radius of the disk over which the plume channel's droplets, "
                                                  "mixed, would collide as often as they do cell by cell "
                                                  "(analysis.channel_clustering); the channel's efficiency is then "
                                                  "collision_efficiency x max(1, (R_c / b)^2): its droplets collide "
                                                  "as if mixed over the disk of radius b, or over the channel where "
                                                  "R_c is narrower (popbal.closures); not with "
                                                  "channel_collision_efficiency; absent: that.", 0.0,
                                          exclusive_minimum=True, optional=True),
        "spread_channel_collision_radius": Field(F, "m", "b_s: channel_collision_radius where the plume spreads "
                                                         "(spread_flux_reynolds; needs channel_collision_radius, the "
                                                         "compact plume's).", 0.0, exclusive_minimum=True,
                                                 optional=True),
        "roof_shear_coefficient": Field(F, "-", "The roof layer's shear rate G in units of u_L / delta, the layer's "
                                                "drainage velocity over its thickness (popbal.closures); absent: "
                                                "shear_coefficient.", 0.0, optional=True),
        "bottom_shear_coefficient": Field(F, "-", "The bottom layer's shear rate G in units of u_s t / h_b, the "
                                                  "plume's droplet velocity over the layer's thickness "
                                                  "(popbal.closures; measured by analysis.calibration.zones."
                                                  "floor_shear_from_collisions); absent: shear_coefficient.", 0.0,
                                          optional=True),
        "bottom_drain_coefficient": Field(F, "-", "The bottom layer's droplets reach the floor at their own hindered "
                                                  "settling velocity plus bottom_drain_coefficient x the plume's "
                                                  "droplet velocity (its discharge driving them into the floor; "
                                                  "popbal.closures); absent: their own settling alone.", 0.0,
                                          optional=True),
        "bottom_lift_share": Field(F, "-", "lambda: of the droplets leaving the bottom layer, the share lambda "
                                           "exp(-(U / u_b)^2) of those whose own hindered settling velocity is U "
                                           "goes up into the outer zone's return flow instead of onto the floor, "
                                           "u_b = bottom_lift_velocity_ratio x u_up the return flow's upflow at the "
                                           "layer's top (droplets slower than it are carried off the floor, by "
                                           "size; popbal.closures); needs a bottom layer and a return flow; absent "
                                           "or 0: none lifted.", 0.0, 1.0, optional=True),
        "bottom_lift_velocity_ratio": Field(F, "-", "u_b / u_up: the upflow at the bottom layer's top that sets "
                                                    "which droplets bottom_lift_share lifts, over the outer zone's "
                                                    "upflow u_up (popbal.closures); needed with bottom_lift_share.",
                                            0.0, exclusive_minimum=True, optional=True),
        "bottom_turning_share": Field(F, "-", "With a bottom layer and a return flow: of what leaves the channel's "
                                              "bottom, the share bottom_turning_share x (1 - min(1, U_h / u_up)) of "
                                              "droplets of hindered settling velocity U_h turns up into the outer "
                                              "zone with the slag instead of entering the bottom layer (the resolved "
                                              "runs' plume gives part of its droplets to the return flow as it "
                                              "turns; popbal.closures); with bottom_turning_form 'uniform' the "
                                              "share is bottom_turning_share for every size; absent or 0: none "
                                              "turns (without a bottom layer the whole 1 - min(1, U_h / u_up) "
                                              "turns).", 0.0, 1.0,
                                      optional=True),
        "bottom_turning_form": Field(S, "", "How bottom_turning_share turns the channel's droplets by size: "
                                            "'selective' (a share T (1 - min(1, U_h / u_up)), the faster settling "
                                            "going on down) or 'uniform' (T for every size: the box-wide "
                                            "circulation takes every size alike, as the resolved runs' turning and "
                                            "settling droplets of equal mean diameter show; popbal.closures."
                                            "turning_share); absent: 'selective'. Needs bottom_turning_share.",
                                     choices=("selective", "uniform"), optional=True),
        "entrainment_length": Field(F, "-", "With a return flow: the outer zone's upflow is u_up s(z) with s = "
                                            "(1 - exp(-(H - z) / (a R))) (1 - exp(-z / (b R))) over its peak, a = "
                                            "entrainment_length and b = turning_length in column radii R, and the "
                                            "plume takes the outer zone's droplets into the channel where the upflow "
                                            "falls with height, at the slag's rate (popbal.closures); absent: u_up "
                                            "at every height, droplets leaving only at the roof.", 0.0,
                                    exclusive_minimum=True, optional=True),
        "turning_length": Field(F, "-", "b of entrainment_length's profile: the return flow starts over about b "
                                        "column radii above the floor (needed with entrainment_length).", 0.0,
                                exclusive_minimum=True, optional=True),
        "axis_velocity_ratio": Field(F, "-", "Slag velocity on the channel axis (the channel_velocity output) / the "
                                             "plume velocity u_c that carries the droplets; absent: 1.", 0.0,
                                     exclusive_minimum=True, optional=True),
        "channel_radius_form": Field(S, "", "How the channel radius R_c is set (popbal.closures): 'inlet' "
                                            "(channel_radius_factor inlet radii), 'flux' (channel_radius_factor x "
                                            "sqrt(Q_ch / (pi u_s)): continuity at a fixed plume volume fraction "
                                            "1 / factor^2, u_s the steady plume velocity) or 'fixed' (R_c = "
                                            "popbal.channel_radius whatever the feed and the box; "
                                            "channel_radius_factor then only says whether there is a channel, 0 "
                                            "for none); absent: 'inlet'.",
                                     choices=("inlet", "flux", "fixed"), optional=True),
        "channel_radius": Field(F, "m", "R_c with channel_radius_form = 'fixed': the compact plume's equivalent core "
                                        "measured in the reference runs, about 10 mm in every compact run of the set "
                                        "(analysis.plume_force.equivalent_core; docs/guide/reduced-model.md), a length "
                                        "with no law yet, so not for boxes far from the set's.", 0.0,
                                exclusive_minimum=True, optional=True),
        "plume_dilution_reynolds": Field(F, "-", "Re_d, with channel_radius_form = 'flux': the plume's volume "
                                                 "fraction is diluted by its Reynolds number, 1 / (factor^2 (1 + Re / "
                                                 "Re_d)), Re = rho_s u_s R_c / mu (popbal.closures); absent: the fixed "
                                                 "1 / factor^2.", 0.0, exclusive_minimum=True, optional=True),
        "plume_reynolds_scale": Field(F, "-", "Re_c: the droplets ride the plume at u_s / (1 + Re / Re_c), Re = "
                                              "rho_s u_s R_c / mu the plume Reynolds number, while the channel_velocity "
                                              "output stays the slag's u_s (popbal.closures); absent: no such "
                                              "reduction.", 0.0, exclusive_minimum=True, optional=True),
        "return_flow_ratio": Field(F, "-", "r: the slag the plume drives down comes back up through the outer zone "
                                           "at u_up = r u_s (u_s the steady plume velocity), where droplets slower than u_up rise "
                                           "to the roof and re-enter the channel, and of the droplets reaching the "
                                           "channel's bottom a share min(1, U / u_up) settles (U their hindered "
                                           "settling velocity), the rest turning into the return flow "
                                           "(popbal.closures); absent or 0: no return flow.", 0.0, optional=True),
        "outer_dispersion": Field(F, "m^2/s", "With a return flow: D, an eddy diffusivity that spreads the outer "
                                              "zone's droplets over the height besides the upflow (the stirring of "
                                              "the box-wide circulation, which keeps droplets faster than the mean "
                                              "upflow suspended in the full runs: each size class decays upward as "
                                              "exp(-(k0 + U / D) z) there, D = 4.8e-4 and 5.0e-4 m^2/s in simple and "
                                              "cubic, python -m analysis.suspension; "
                                              "popbal.kernels.transport_two_way); absent or 0: none.", 0.0,
                                   optional=True),
        "confinement": Field(B, "", "true: the plume coefficient and the return flow follow the confined Stokes "
                                    "plume of the channel (radius R_c) in the column of the box's cross-section "
                                    "(radius R = sqrt(W D / pi)): u_s = sqrt(c_ch c(R/R_c) Q drho g / (pi mu)) and "
                                    "u_up = r S(R/R_c) u_s, so channel_coefficient and return_flow_ratio become "
                                    "multipliers of the laws (1: as derived; popbal.closures); absent or false: "
                                    "constants.", optional=True),
        "plume_law": Field(S, "", "With confinement = true, the confined plume's coefficient c(R/R_c): "
                                  "'uniform_core' (a core of radius R_c at uniform load, c = A0^2 / (4 Am)) or "
                                  "'line_force' (the load as a line force on the axis, c = A0 / 4, as the full runs' "
                                  "compact plumes measure it; popbal.closures); absent: 'uniform_core'.",
                           choices=("uniform_core", "line_force"), optional=True),
        "busy_partners": Field(B, "", "true: a droplet merges with one partner at a time, as in the full engine's "
                                      "delayed coalescence, where a marked pair is busy for its growth time t_jk = "
                                      "max(growth_target d_m - d_small, 0) / (growth_rate d_m) (coalescence keys): "
                                      "each partner's kernel is discounted by the share of time it is free, "
                                      "f_j = 1 / (1 + sum_k beta_jk N_k t_jk) (a handling time; popbal.kernels."
                                      "busy_discount); absent or false: every collision can merge at once.",
                               optional=True),
    },
}
del F, I, B, S, L


def _record_class(section: str, fields: dict[str, Field]):
    return dataclasses.make_dataclass(
        section.capitalize(), [(k, Any) for k in fields], frozen=True,
        namespace={"__doc__": f"Validated [{section}] section; keys and units in settler.cases.SCHEMA."})


RECORDS = {section: _record_class(section, fields) for section, fields in SCHEMA.items()}


@dataclass(frozen=True)
class Case:
    """A resolved, validated case. Sections are records with the keys of :data:`SCHEMA` (SI units)."""

    case: Any
    geometry: Any
    slag: Any
    matte: Any
    feed: Any
    drag: Any
    coalescence: Any
    reaction: Any
    fulldem: Any
    popbal: Any
    source: str = ""

    # Derived properties: computed in one place so every engine sees the same numbers.
    @property
    def slag_viscosity(self) -> float:
        """Slag viscosity at the run temperature, Arrhenius law [Pa s]."""
        s = self.slag
        return slag_viscosity(s.temperature, s.viscosity_reference, s.reference_temperature, s.activation_energy)

    @property
    def x_initial(self) -> float:
        """Cu2S mole fraction of the fed matte, from its density by Eq. 4 [-]."""
        return cu2s_fraction_from_density(self.matte.density)

    @property
    def x_final(self) -> float:
        """End state X_inf of the reaction fit [-] (fixed, or Cantera equilibrium)."""
        r = self.reaction
        if r.end_state == "fixed":
            return r.x_final
        from .thermo import equilibrium_grade  # Cantera is imported only when needed

        return float(equilibrium_grade(self.slag.temperature, r.oxygen_pressure, p_so2=r.so2_pressure,
                                       a_feo=r.feo_activity))

    @property
    def inlet_center(self) -> tuple[float, float]:
        """(x, y) of the inlet centre [m]."""
        g = self.geometry
        if g.inlet_center is None:
            return (0.5 * g.width, 0.5 * g.depth)
        return tuple(g.inlet_center)

    @property
    def inlet_is_slot(self) -> bool:
        """Whether the inlet is a slot (geometry.inlet_length given) rather than a disk."""
        return self.geometry.inlet_length is not None

    @property
    def inlet_area(self) -> float:
        """Area of the inlet on the top surface [m^2]: the disk's pi d^2 / 4, or the slot's length x width."""
        g = self.geometry
        return g.inlet_length * g.inlet_diameter if self.inlet_is_slot else math.pi * 0.25 * g.inlet_diameter**2

    @property
    def has_outlet(self) -> bool:
        return self.geometry.outlet_diameter > 0.0

    def to_dict(self) -> dict:
        """Plain nested dict of the resolved values (what is written beside every output)."""
        out = {}
        for section in SCHEMA:
            record = getattr(self, section)
            out[section] = {k: v for k, v in dataclasses.asdict(record).items() if v is not None}
        return out

    def to_toml(self) -> str:
        """The resolved case as TOML, with units as comments."""
        lines = [f"# resolved case; loaded from {self.source}" if self.source else "# resolved case"]
        for section, values in self.to_dict().items():
            lines.append(f"\n[{section}]")
            for key, value in values.items():
                unit = SCHEMA[section][key].unit
                lines.append(f"{key} = {_toml_value(value)}" + (f"  # [{unit}]" if unit and unit != "-" else ""))
        return "\n".join(lines) + "\n"

    def replace(self, **overrides) -> "Case":
        """A new validated case with ``section.key`` overrides applied (keyword form: section__key=value)."""
        return resolve(self.to_dict(), {k.replace("__", "."): v for k, v in overrides.items()}, self.source)


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return repr(value)


# ----------------------------------------------------------------------------------------------------------- loading
def list_presets() -> list[str]:
    """Names of the case presets shipped in data/cases/; CaseError if there are none (a broken installation)."""
    folder = DATA_DIR / "cases"
    names = preset_names(DATA_DIR)
    if not names:
        raise CaseError(f"no case presets (*.toml) in {folder} (data folder from {DATA_DIR_SOURCE}); allowed: a "
                        "data folder holding cases/ and properties/: set SETTLER_DATA to one, or reinstall settler")
    return names


def _read_toml(path: Path, what: str) -> dict:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise CaseError(f"{what} file {path} does not exist") from None
    except IsADirectoryError:
        raise CaseError(f"{what} file {path} is a folder; allowed: a TOML file") from None
    except UnicodeDecodeError as exc:
        raise CaseError(f"{what} file {path} is not UTF-8 text (byte {exc.object[exc.start:exc.start + 1]!r} at "
                        f"offset {exc.start}); allowed: a UTF-8 TOML file") from None
    except tomllib.TOMLDecodeError as exc:
        raise CaseError(f"{what} file {path} is not valid TOML: {exc}") from None
    except OSError as exc:
        raise CaseError(f"{what} file {path} cannot be read: {exc.strerror or exc}") from None


def case_path(name_or_path: str | os.PathLike) -> Path:
    """Path of a preset name (``simple``) or of a case file path. A folder of a preset's name (a run's output, say
    ``settler full simple --out simple``) does not hide the preset."""
    p = Path(name_or_path)
    preset = DATA_DIR / "cases" / f"{name_or_path}.toml"
    if p.is_dir() and p.suffix != ".toml" and preset.is_file():
        return preset
    if p.suffix == ".toml" or p.exists():
        return p
    if not preset.exists():
        raise CaseError(f"case {str(name_or_path)!r} is neither a file nor a preset; presets: "
                        + ", ".join(list_presets()))
    return preset


def parse_override(text: str) -> tuple[str, Any]:
    """Split ``section.key=value``; the value is read as TOML (``0.3``, ``true``, ``[0.1, 0.1]``) or else a string."""
    if "=" not in text:
        raise CaseError(f"override {text!r} is not of the form section.key=value")
    key, raw = (t.strip() for t in text.split("=", 1))
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key, value


def load_case(name_or_path: str | os.PathLike, overrides: dict[str, Any] | list[str] | None = None) -> Case:
    """Load, merge and validate a case.

    name_or_path: a preset name (``cubic``, ``simple``, ``deep``, ...) or a path to a TOML case file.
    overrides: ``{"slag.viscosity_reference": 0.3}`` or a list of ``"section.key=value"`` strings.
    """
    path = case_path(name_or_path)
    raw = _read_toml(path, "case")
    return resolve(raw, overrides, str(path))


def case_with_overrides(case: "str | os.PathLike | Case", overrides: dict | list | None = None,
                        **keyword_overrides) -> Case:
    """A validated case from a preset name, a TOML path or a :class:`Case`, with overrides given as
    ``{"section.key": value}``, ``["section.key=value"]`` or keywords ``section__key=value`` (later ones win): the
    one way the engines' Python APIs (``popbal.setup``, ``fulldem.setup``) take a case."""
    if isinstance(overrides, (list, tuple)):
        overrides = dict(parse_override(o) for o in overrides)
    merged = {**(overrides or {}), **{k.replace("__", "."): v for k, v in keyword_overrides.items()}}
    if isinstance(case, Case):
        return case.replace(**{k.replace(".", "__"): v for k, v in merged.items()}) if merged else case
    return load_case(case, merged)


def resolve(raw: dict, overrides=None, source: str = "") -> Case:
    """Merge a raw case dict over its property set, apply overrides and validate."""
    if isinstance(overrides, (list, tuple)):
        overrides = dict(parse_override(o) for o in overrides)
    overrides = dict(overrides or {})
    prop_name = overrides.get("case.properties", raw.get("case", {}).get("properties"))
    calibration = overrides.get("case.calibration", raw.get("case", {}).get("calibration"))
    merged: dict[str, dict] = {}
    if prop_name is not None:
        if not isinstance(prop_name, str):
            raise CaseError(f"case.properties = {prop_name!r}: allowed: a property-set name, one of "
                            + ", ".join(sorted(p.stem for p in (DATA_DIR / "properties").glob("*.toml"))))
        ppath = DATA_DIR / "properties" / f"{prop_name}.toml"
        if not ppath.exists():
            raise CaseError(f"case.properties = {prop_name!r}: no property set {ppath}; available: "
                            + ", ".join(sorted(p.stem for p in (DATA_DIR / "properties").glob("*.toml"))))
        _merge(merged, _read_toml(ppath, "property set"), f"property set {prop_name}")
    # A layer named in the file sits under the file's own values; a layer named by an override sits over them,
    # so that case.calibration=NAME applies NAME's values to any case file, a run's resolved case.toml included.
    layer_over_file = "case.calibration" in overrides
    if calibration is not None and calibration != NO_CALIBRATION and not layer_over_file:
        _merge(merged, read_calibration(calibration), f"calibration layer {calibration}")
    file_layer = raw.get("case", {}).get("calibration")
    if layer_over_file and file_layer not in (None, NO_CALIBRATION, calibration):
        raw = _without_layer(raw, file_layer)  # the file's own layer gives way to the override's (or to none)
    _merge(merged, raw, source or "case")
    if calibration is not None and calibration != NO_CALIBRATION and layer_over_file:
        _merge(merged, read_calibration(calibration), f"calibration layer {calibration}")
    for key, value in overrides.items():
        section, _, name = key.partition(".")
        if not name:
            raise CaseError(f"override {key!r}: give section.key, e.g. slag.viscosity_reference=0.3")
        _check_known(section, name, f"override {key}")
        merged.setdefault(section, {})[name] = value
    return _validate(merged, source)


def _without_layer(raw: dict, layer: str) -> dict:
    """``raw`` without the keys that calibration layer ``layer`` sets (in a run's resolved case.toml they came from
    that layer, perhaps from an older version of it, so whatever their value), so that another layer, or none,
    named by an override replaces the whole of it; ``raw`` unchanged if the layer no longer exists."""
    try:
        sections = read_calibration(layer)
    except CaseError:
        return raw
    out = {name: dict(table) if isinstance(table, dict) else table for name, table in raw.items()}
    for section, values in sections.items():
        table = out.get(section)
        if isinstance(table, dict):
            for key, value in values.items():
                table.pop(key, None)
    return out


#: Value of case.calibration that applies no layer (so an override can switch a preset's layer off).
NO_CALIBRATION = "none"
#: Table of a calibration layer that records where its values come from; not case keys, so not merged.
PROVENANCE_TABLE = "provenance"


#: Files of data/calibration/ that are not layers: the pre-registered hold-outs of the calibration.
CALIBRATION_REGISTRIES = ("holdouts",)


def calibration_path(name: str) -> Path:
    """Path of the calibration layer ``name`` (data/calibration/<name>.toml)."""
    return DATA_DIR / "calibration" / f"{name}.toml"


def read_calibration(name) -> dict:
    """The case sections of calibration layer ``name`` (its [provenance] table left out); CaseError if absent."""
    folder = DATA_DIR / "calibration"
    if not isinstance(name, str) or not calibration_path(name).is_file() or name in CALIBRATION_REGISTRIES:
        available = ", ".join(sorted(p.stem for p in folder.glob("*.toml") if p.stem not in CALIBRATION_REGISTRIES))
        available = available or "none"
        what = "is the calibration's hold-out registry, not a layer" if name in CALIBRATION_REGISTRIES else \
            f"no calibration layer {folder / f'{name}.toml'}"
        raise CaseError(f"case.calibration = {name!r}: {what}; available: {available}")
    layer = _read_toml(calibration_path(name), "calibration layer")
    layer.pop(PROVENANCE_TABLE, None)
    return layer


def _check_known(section: str, key: str | None, where: str):
    if section not in SCHEMA:
        raise CaseError(f"{where}: unknown section [{section}]; allowed sections: " + ", ".join(SCHEMA))
    if key is not None and key not in SCHEMA[section]:
        raise CaseError(f"{where}: unknown key {section}.{key}; allowed keys in [{section}]: "
                        + ", ".join(SCHEMA[section]))


def _merge(into: dict, layer: dict, where: str):
    for section, values in layer.items():
        if not isinstance(values, dict):
            raise CaseError(f"{where}: top-level key {section!r} must be a [section] table; allowed sections: "
                            + ", ".join(SCHEMA))
        _check_known(section, None, where)
        for key, value in values.items():
            _check_known(section, key, where)
            into.setdefault(section, {})[key] = value


def _coerce(section: str, key: str, field: Field, value):
    name = f"{section}.{key}"
    if value is None:
        if field.optional:
            return None
        raise CaseError(f"{name} is missing: allowed: {field.allowed()} [{field.unit}] ({field.doc})")
    if field.kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise CaseError(f"{name} = {value!r}: wrong type, allowed: {field.allowed()}")
        value = float(value)
        if not math.isfinite(value):
            raise CaseError(f"{name} = {value!r}: must be finite, allowed: {field.allowed()}")
    elif field.kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise CaseError(f"{name} = {value!r}: wrong type, allowed: {field.allowed()}")
    elif field.kind is bool:
        if not isinstance(value, bool):
            raise CaseError(f"{name} = {value!r}: wrong type, allowed: {field.allowed()}")
    elif field.kind is str:
        if not isinstance(value, str):
            raise CaseError(f"{name} = {value!r}: wrong type, allowed: {field.allowed()}")
    elif field.kind is list:
        if (not isinstance(value, (list, tuple)) or len(value) != (field.length or len(value)) or not value
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
            raise CaseError(f"{name} = {value!r}: allowed: {field.allowed()}")
        value = [float(v) for v in value]
    if field.choices is not None and value not in field.choices:
        raise CaseError(f"{name} = {value!r}: allowed: {field.allowed()}")
    if field.kind in (float, int):
        low_bad = field.minimum is not None and (
            value <= field.minimum if field.exclusive_minimum else value < field.minimum)
        high_bad = field.maximum is not None and value > field.maximum
        if low_bad or high_bad:
            raise CaseError(f"{name} = {value!r} {field.unit}: out of range, allowed: {field.allowed()}")
    return value


def _validate(merged: dict, source: str) -> Case:
    sections = {}
    for section, fields in SCHEMA.items():
        values = merged.get(section, {})
        coerced = {k: _coerce(section, k, f, values.get(k)) for k, f in fields.items()}
        sections[section] = RECORDS[section](**coerced)
    case = Case(**sections, source=source)
    _check_consistency(case)
    return case


def _fail(key: str, value, allowed: str):
    raise CaseError(f"{key} = {value!r}: {allowed}")


def _check_feed_table(f):
    """The 'table' feed distribution: matching lists, positive diameters, fractions >= 0 summing to 1."""
    if f.table_diameters is None or f.table_mass_fractions is None:
        _fail("feed.distribution", f.distribution, "'table' needs feed.table_diameters and feed.table_mass_fractions")
    if len(f.table_diameters) != len(f.table_mass_fractions):
        _fail("feed.table_mass_fractions", f.table_mass_fractions,
              f"needs one entry per feed.table_diameters entry ({len(f.table_diameters)})")
    if min(f.table_diameters) <= 0.0:
        _fail("feed.table_diameters", f.table_diameters, "allowed: diameters > 0 m")
    if min(f.table_mass_fractions) < 0.0 or abs(sum(f.table_mass_fractions) - 1.0) > 1e-6:
        _fail("feed.table_mass_fractions", f.table_mass_fractions, "allowed: fractions >= 0 that sum to 1 (+- 1e-6)")


def _check_consistency(case: Case):
    """Checks that involve several keys."""
    g, f, s = case.geometry, case.feed, case.slag
    mu = case.slag_viscosity
    if not (math.isfinite(mu) and mu > 0.0):
        raise CaseError(f"slag.activation_energy = {s.activation_energy:g} J/mol with slag.temperature = "
                        f"{s.temperature:g} K: the Arrhenius law gives a slag viscosity of {mu!r} Pa s (from "
                        f"slag.viscosity_reference = {s.viscosity_reference:g} Pa s at slag.reference_temperature = "
                        f"{s.reference_temperature:g} K); allowed: values that give a finite viscosity > 0")
    cx, cy = case.inlet_center
    r_in = 0.5 * g.inlet_diameter
    if g.inlet_length is not None:
        half = 0.5 * g.inlet_length
        if not (half <= cx <= g.width - half and r_in <= cy <= g.depth - r_in):
            if g.inlet_length > g.width or (g.inlet_center is None and g.inlet_diameter <= g.depth):
                key, value = "geometry.inlet_length", g.inlet_length
            elif g.inlet_diameter > g.depth:
                key, value = "geometry.inlet_diameter", g.inlet_diameter
            else:
                key, value = "geometry.inlet_center", list(g.inlet_center)
            _fail(key, value,
                  f"the slot inlet ({g.inlet_length:g} x {g.inlet_diameter:g} m centred at ({cx:g}, {cy:g}) m) must "
                  f"lie inside the top face {g.width:g} x {g.depth:g} m")
        if case.slag.feed_rate > 0.0:
            _fail("slag.feed_rate", case.slag.feed_rate,
                  "a slot inlet (geometry.inlet_length) feeds matte only: allowed 0, or a disk inlet (no inlet_length)")
    elif not (r_in <= cx <= g.width - r_in and r_in <= cy <= g.depth - r_in):
        _fail("geometry.inlet_center" if g.inlet_center is not None else "geometry.inlet_diameter",
              list(g.inlet_center) if g.inlet_center is not None else g.inlet_diameter,
              f"the inlet disk (diameter {g.inlet_diameter:g} m centred at ({cx:g}, {cy:g}) m) must lie inside "
              f"the top face {g.width:g} x {g.depth:g} m")
    if g.outlet_diameter > 0.0:
        r_out = 0.5 * g.outlet_diameter
        wall_width = g.depth if g.outlet_side in ("x-", "x+") else g.width
        if g.outlet_diameter > min(wall_width, g.height):
            _fail("geometry.outlet_diameter", g.outlet_diameter,
                  f"must fit the {g.outlet_side} wall ({wall_width:g} x {g.height:g} m), allowed "
                  f"<= {min(wall_width, g.height):g} m")
        if not (r_out <= g.outlet_height <= g.height - r_out):
            _fail("geometry.outlet_height", g.outlet_height,
                  f"the outlet (diameter {g.outlet_diameter:g} m) must lie inside the side wall: allowed "
                  f"{r_out:g} <= outlet_height <= {g.height - r_out:g} m")
    elif case.slag.feed_rate > 0.0:
        _fail("slag.feed_rate", case.slag.feed_rate,
              "a closed box (geometry.outlet_diameter = 0) cannot take a slag feed: allowed 0, or give an outlet")
    if case.matte.density <= case.slag.density:
        _fail("matte.density", case.matte.density,
              f"must exceed slag.density = {case.slag.density:g} kg/m^3 for droplets to settle")
    if not f.scale_min <= 1.0 <= f.scale_max:
        _fail("feed.scale_min", f.scale_min, f"allowed scale_min <= 1 <= scale_max (scale_max = {f.scale_max:g})")
    if f.distribution == "table":
        _check_feed_table(f)
        largest_fed, what = max(f.table_diameters), "max(feed.table_diameters)"
    else:
        largest_fed, what = f.mean_diameter * f.scale_max, "feed.mean_diameter x feed.scale_max"
    if case.coalescence.enabled and case.coalescence.size_limit < largest_fed:
        _fail("coalescence.size_limit", case.coalescence.size_limit,
              f"must be at least the largest fed droplet, {what} = {largest_fed:g} m")
    if case.reaction.enabled:
        x0 = case.x_initial
        if not 0.0 < x0 < 1.0:
            _fail("matte.density", case.matte.density,
                  f"with reactions on, it sets the Cu2S fraction by Eq. 4, which needs "
                  f"{matte_density(0.0):g} < density < {matte_density(1.0):g} kg/m^3")
        if case.reaction.end_state == "fixed" and not x0 < case.reaction.x_final <= 1.0:
            _fail("reaction.x_final", case.reaction.x_final,
                  f"must exceed the feed's Cu2S fraction X0 = {x0:.4f} (from matte.density) and be <= 1")
