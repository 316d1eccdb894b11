"""Compiled kernels of the reduced model: coalescence (cell-average technique), collision frequency, transport in z,
reaction and per-cell droplet properties.

Kernel rules (STYLE.md): ``@njit(cache=True)`` functions of arrays and scalars only -- no case objects, no pandas,
no files; work arrays come from the caller, so the per-pair and per-cell loops allocate nothing. Every droplet law
is the shared one from :mod:`settler.physics` (coalescence probability, reaction fit, density and size with age,
hindered settling); the single-droplet settling velocity arrives as a table the driver fills from
:func:`settler.derived.settling_velocity`, and the plume velocity is :func:`popbal.closures.cloud_velocity`. The
pair and transport kernels (cell-average rates, collision kernel, upwind sweep) have plain-NumPy twins in
:mod:`popbal.reference` that the tests require to agree; the time integrators are checked against the
Smoluchowski solutions and the reaction and property kernels against the shared laws they call.

Glossary and layout (SI units throughout):

* K sections (pivots x_k [m^3] of *original* droplet volume, see :mod:`popbal.grid`), J cells in z (index 0 at the
  bottom, uniform height dz [m]), Q = 3 carried quantities per section and cell, stored as ``content[..., q, k]``:

  - q = 0 ``NUMBER``: number density N [1/m^3 of slag];
  - q = 1 ``AGE``: age moment, sum over droplets of v0 * age, per unit slag volume [s m^3/m^3] -- the seed
    paper's volume-weighted age on coalescence; mean age of a section = AGE / (N x_k);
  - q = 2 ``FES_REMOVED``: FeS mass removed by the reaction from the droplets now present [kg/m^3].

* A droplet of section k therefore weighs rho_0 x_k - FES_REMOVED/N [kg] (rho_0 the feed matte density), which makes
  the mass accounting exact: every operation (transport, coalescence, feed, sink) moves N and FES_REMOVED together
  and linearly, and the reaction changes only FES_REMOVED, by an amount booked as reacted.

Why carry FeS removed rather than only an age: upwind transport and the cell-average redistribution *mix* droplets
of different ages. A mean-field age moment mixed linearly does not conserve FeS (the FeS left is a nonlinear
function of age), so the mass balance could only be closed by a fudge. FeS removed is additive, so mixing conserves
it exactly; the section's age for the reaction fit is then its *composition age* -- the age at which a fed droplet
reaches the section's mean composition (settler.physics.reaction_age), the rule the shared physics uses for a
coalesced droplet. The volume-weighted age moment is carried beside it for output and for runs without reaction.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# The coalescence rules (registry, codes, and merger_efficiency, which applies a rule to seed Eq. 2) are shared with
# the CFD-DEM engine, so they live in settler.physics; imported here under their old names.
from settler.physics import (COALESCENCE_RULES, RULE_PROBABILITY, RULE_STEP, coalescence_probability,  # noqa: F401
                             composition_from_masses, density_at_age, growth_time, merger_efficiency, reacted_mass,
                             reaction_age, relative_diameter_at_age, richardson_zaki_factor, species_masses)

from .closures import cloud_velocity

NUMBER, AGE, FES_REMOVED = 0, 1, 2
QUANTITIES = 3

#: Cells, and sections within a cell, holding a matte volume fraction below this take no part in coalescence
#: (rates ~ phi^2 are nil there) nor in the Courant limit of the time step [-].
NEGLIGIBLE_VOLUME_FRACTION = 1e-14
#: Most sweeps of busy_discount's averaged substitution (each at least halves the error; 60 reach round-off).
MAX_BUSY_SWEEPS = 60

#: Largest composition age [time constants] a section may be given; the reaction fit is flat there (e^-50).
AGE_CAP_TIME_CONSTANTS = 50.0


# ------------------------------------------------------------------------------------------------- coalescence
# Why pair lists: in a furnace column most of a cell's K sections hold (next to) nothing most of the time, and the
# step rule zeroes many of the remaining pairs, so the K (K + 1) / 2 pair loop mostly skips. collision_pairs lists,
# once per cell and step, the pairs that can merge (both sections occupied, beta > 0), in the (j, k) order of the
# full loop; pair_rates and largest_death_rate then visit only those, across every sub-step. Skipped pairs
# contributed exact zeros, and the list keeps the order of every non-zero term, so results are bit-identical to
# the full loops (cell_average_rates, collision_kernel, which the NumPy twins check).
@njit(cache=True)
def redistribute_births(pivots, births, rates, carried):
    """Add the cell-average births (number B_i, volume V_i, carried quantities, collected in births (Q + 1, K)) to
    rates (Q, K): vbar = V_i / B_i [m^3] is split between pivot i and its neighbour on vbar's side so that number
    and volume are conserved; carried quantities follow the volume. Rows q >= carried are zero and left alone."""
    n_k = pivots.size
    for i in range(n_k):
        b = births[0, i]
        if b <= 0.0:
            continue
        vbar = births[1, i] / b
        if not vbar > 0.0:
            vbar = pivots[i]  # the volume underflowed (denormal birth rates in a far tail): keep it on the pivot
        neighbour = i + 1 if vbar >= pivots[i] else i - 1
        if neighbour < 0 or neighbour >= n_k:
            # vbar beyond an end pivot only by round-off: keep the volume on pivot i
            rates[NUMBER, i] += births[1, i] / pivots[i]
            for q in range(1, carried):
                rates[q, i] += births[q + 1, i]
            continue
        a = (pivots[neighbour] - vbar) / (pivots[neighbour] - pivots[i])
        rates[NUMBER, i] += a * b
        rates[NUMBER, neighbour] += (1.0 - a) * b
        share = a * pivots[i] / vbar
        for q in range(1, carried):
            rates[q, i] += share * births[q + 1, i]
            rates[q, neighbour] += (1.0 - share) * births[q + 1, i]


@njit(cache=True)
def pair_rates(content, pivots, pair_j, pair_k, pair_target, pair_beta, pairs, carried, births, rates):
    """Coalescence rates of one cell by the cell-average technique over a pair list (see :func:`collision_pairs`).

    content (Q, K); pair_j, pair_k, pair_target (P,) int64 and pair_beta (P,) [m^3/s]: the first ``pairs`` entries
    are the merging pairs j <= k, the cell their merger lands in and the kernel beta_jk. Rows q >= carried of
    content are zero (e.g. FES_REMOVED without reaction) and are skipped. births (Q + 1, K) is work space; writes
    d content/dt into rates (Q, K). Otherwise as :func:`cell_average_rates`.
    """
    births[:, :] = 0.0
    rates[:, :] = 0.0
    for p in range(pairs):
        j = pair_j[p]
        nj = content[NUMBER, j]
        if nj <= 0.0:
            continue
        k = pair_k[p]
        nk = content[NUMBER, k]
        if nk <= 0.0:
            continue
        r = pair_beta[p] * nj * nk
        if r == 0.0:
            continue
        if j == k:
            r *= 0.5
        i = pair_target[p]
        births[0, i] += r
        births[1, i] += r * (pivots[j] + pivots[k])
        rates[NUMBER, j] -= r
        rates[NUMBER, k] -= r
        for q in range(1, carried):
            from_j = r * content[q, j] / nj
            from_k = r * content[q, k] / nk
            births[q + 1, i] += from_j + from_k
            rates[q, j] -= from_j
            rates[q, k] -= from_k
    redistribute_births(pivots, births, rates, carried)


@njit(cache=True)
def list_pairs(target, beta, pair_j, pair_k, pair_target, pair_beta):
    """Every pair j <= k with target >= 0 and beta_jk != 0, in (j, k) order, into the pair arrays (P >= K (K + 1)
    / 2); returns how many. For a kernel fixed over many calls (integrate_cell, cell_average_rates)."""
    n_k = target.shape[0]
    pairs = 0
    for j in range(n_k):
        for k in range(j, n_k):
            i = target[j, k]
            if i < 0:
                break  # pivots increase with k, so every larger partner exceeds the limit too
            if beta[j, k] != 0.0:
                pair_j[pairs] = j
                pair_k[pairs] = k
                pair_target[pairs] = i
                pair_beta[pairs] = beta[j, k]
                pairs += 1
    return pairs


@njit(cache=True)
def cell_average_rates(content, pivots, target, beta, births, rates):
    """Coalescence rates of one cell by the cell-average technique (Kumar et al. 2006, Chem. Eng. Sci. 61, 3327).

    content (Q, K): row NUMBER = N_i [1/m^3], other rows droplet-carried extensive quantities [unit/m^3].
    pivots (K,) [m^3]; target (K, K) cell of each merger or -1 (see popbal.grid.SectionGrid); beta (K, K)
    symmetric coalescence kernel [m^3/s]. births (Q + 1, K) is work space. Writes d content/dt into rates (Q, K).

    Births are first collected per cell (number B_i, volume V_i, carried quantities), then the cell's mean newborn
    volume vbar = V_i/B_i is split between pivot i and its neighbour on vbar's side so that number and volume are
    conserved; carried quantities follow the volume (a newborn keeps its quantity per unit volume). Deaths remove
    each parent with its own quantity. Number and volume of every merger are conserved exactly, so the first
    moment is invariant to round-off. Lists the pairs (allocating) and calls :func:`pair_rates`: for one-off calls
    and the tests; the time loop keeps its pair list over the sub-steps.
    """
    n_q, n_k = content.shape
    size = n_k * (n_k + 1) // 2
    pair_j, pair_k, pair_target = np.empty(size, np.int64), np.empty(size, np.int64), np.empty(size, np.int64)
    pair_beta = np.empty(size)
    pairs = list_pairs(target, beta, pair_j, pair_k, pair_target, pair_beta)
    pair_rates(content, pivots, pair_j, pair_k, pair_target, pair_beta, pairs, n_q, births, rates)


@njit(cache=True)
def largest_death_rate(content, sections, count, target, beta, loss_weight):
    """max_i sum_k beta_ik N_k w_ik [1/s]: the fastest net per-droplet coalescence rate of a cell (sets sub-steps).

    Only the first ``count`` entries of ``sections`` (ascending section indices) are visited: beta must be 0 for
    every other section (the occupied sections of collision_pairs, or all sections). w_ik = SectionGrid.loss_weight
    discounts mergers that land back in the larger droplet's own cell, whose gross rate the cell-average birth
    nearly cancels, so a big droplet sweeping up fines does not force tiny steps.
    """
    largest = 0.0
    for a in range(count):
        i = sections[a]
        s = 0.0
        for b in range(count):
            k = sections[b]
            if target[i, k] < 0:
                break
            s += beta[i, k] * content[NUMBER, k] * loss_weight[i, k]
        largest = max(largest, s)
    return largest


@njit(cache=True)
def carried_rows(content):
    """1 + the last row q >= 1 of content (Q, K) holding a non-zero value (1 if none): rows from there on are zero
    and stay zero under coalescence, so the rate loops skip them (FES_REMOVED without reaction)."""
    n_q, n_k = content.shape
    for q in range(n_q - 1, 0, -1):
        for k in range(n_k):
            if content[q, k] != 0.0:
                return q + 1
    return 1


@njit(cache=True)
def coalesce_cell(content, pivots, sections, count, target, loss_weight, beta, pair_j, pair_k, pair_target,
                  pair_beta, pairs, dt, max_rate_step, births, k1, k2, trial):
    """Advance one cell's coalescence by dt [s] with Heun's method (RK2), in sub-steps h <= max_rate_step / rate.

    content (Q, K) is updated in place; sections, count, beta: as for :func:`largest_death_rate`; the pair list as
    for :func:`pair_rates`; births (Q + 1, K), k1, k2, trial (Q, K) are work space. Heun's method conserves every
    linear invariant (number-weighted volume, carried quantities) to round-off; the sub-step bound keeps it
    positive (h times the fastest death rate <= max_rate_step, 0.5 by default). Returns the sub-steps taken.
    """
    rate = largest_death_rate(content, sections, count, target, beta, loss_weight)
    steps = max(1, int(math.ceil(dt * rate / max_rate_step)))
    h = dt / steps
    n_k = content.shape[1]
    carried = carried_rows(content)
    for _ in range(steps):
        pair_rates(content, pivots, pair_j, pair_k, pair_target, pair_beta, pairs, carried, births, k1)
        for q in range(carried):
            for k in range(n_k):
                trial[q, k] = content[q, k] + h * k1[q, k]
        pair_rates(trial, pivots, pair_j, pair_k, pair_target, pair_beta, pairs, carried, births, k2)
        for q in range(carried):
            for k in range(n_k):
                content[q, k] += 0.5 * h * (k1[q, k] + k2[q, k])
    return steps


@njit(cache=True)
def integrate_cell(content, pivots, target, loss_weight, beta, duration, max_rate_step, max_step):
    """0-D coalescence with classical RK4 over ``duration`` [s] (verification against Smoluchowski solutions).

    The step is min(max_step, max_rate_step / fastest death rate), so the explicit scheme stays stable even where
    the grid reaches volumes whose death rate is far above the dynamics (the sum and product kernels). RK4
    conserves the first moment to round-off. content (Q, K) is updated in place; returns the number of steps.
    """
    n_q, n_k = content.shape
    births = np.empty((n_q + 1, n_k))
    k1 = np.empty((n_q, n_k))
    k2 = np.empty((n_q, n_k))
    k3 = np.empty((n_q, n_k))
    k4 = np.empty((n_q, n_k))
    trial = np.empty((n_q, n_k))
    every = np.arange(n_k)
    size = n_k * (n_k + 1) // 2
    pair_j, pair_k, pair_target = np.empty(size, np.int64), np.empty(size, np.int64), np.empty(size, np.int64)
    pair_beta = np.empty(size)
    pairs = list_pairs(target, beta, pair_j, pair_k, pair_target, pair_beta)
    t = 0.0
    steps = 0
    while t < duration:
        rate = largest_death_rate(content, every, n_k, target, beta, loss_weight)
        h = min(max_step, duration - t)
        if rate > 0.0:
            h = min(h, max_rate_step / rate)
        pair_rates(content, pivots, pair_j, pair_k, pair_target, pair_beta, pairs, n_q, births, k1)
        trial[:, :] = content + 0.5 * h * k1
        pair_rates(trial, pivots, pair_j, pair_k, pair_target, pair_beta, pairs, n_q, births, k2)
        trial[:, :] = content + 0.5 * h * k2
        pair_rates(trial, pivots, pair_j, pair_k, pair_target, pair_beta, pairs, n_q, births, k3)
        trial[:, :] = content + h * k3
        pair_rates(trial, pivots, pair_j, pair_k, pair_target, pair_beta, pairs, n_q, births, k4)
        content += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        t = duration if duration - t <= h else t + h
        steps += 1
    return steps


@njit(cache=True)
def merger_speed_limit(diameter_a, diameter_b, density_droplet, density_slag, interfacial_tension, psi,
                       virtual_mass, form, threshold):
    """Largest approach speed [m/s] at which P_c >= threshold (bisection on the shared seed Eq. 2).

    P_c falls monotonically with the approach speed (it is exp(-c sqrt(We)), We ~ u^2), so the 'step' rule is
    u <= this limit. Tabulated once per run when droplet sizes and densities are fixed (no reaction), it replaces
    two evaluations of Eq. 2 per pair and cell by a comparison; inf if P_c never drops below the threshold.
    """
    if threshold <= 0.0:
        return math.inf
    high = 1.0
    while coalescence_probability(diameter_a, diameter_b, high, density_droplet, density_slag, interfacial_tension,
                                  psi, virtual_mass, form) >= threshold:
        high *= 2.0
        if high > 1e12:
            return math.inf
    low = 0.0
    for _ in range(200):
        mid = 0.5 * (low + high)
        if coalescence_probability(diameter_a, diameter_b, mid, density_droplet, density_slag, interfacial_tension,
                                   psi, virtual_mass, form) >= threshold:
            low = mid
        else:
            high = mid
        if high - low <= 1e-14 * high:
            break
    return low


@njit(cache=True)
def pair_kernel(diameter_j, diameter_k, velocity_j, velocity_k, density_j, density_k, speed_limit, tabulated,
                shear_rate, density_slag, interfacial_tension, psi, virtual_mass, form, threshold, rule, efficiency):
    """Coalescence kernel beta [m^3/s] of one pair: collision frequency x efficiency x merger fraction.

    Differential settling (Smoluchowski 1917; Friedlander 2000 eq. 7.56): (pi/4)(d_j + d_k)^2 |v_j - v_k|, approach
    speed |v_j - v_k|. Laminar shear (Smoluchowski 1917): (1/6) G (d_j + d_k)^3, approach speed G (d_j + d_k)/2.
    Each mechanism's collisions merge by :func:`merger_efficiency` at its own approach speed, or, when
    ``tabulated``, by the step rule's speed_limit [m/s] of the pair (:func:`merger_speed_limit`); ``efficiency`` is
    the collision efficiency (a calibration parameter). Diameters [m], velocities [m/s], densities [kg/m^3],
    shear_rate G [1/s].
    """
    d_sum = diameter_j + diameter_k
    rho = 0.5 * (density_j + density_k)
    dv = abs(velocity_j - velocity_k)
    shear_speed = 0.5 * shear_rate * d_sum
    b = 0.0
    if dv > 0.0:
        if tabulated:
            e = 1.0 if dv <= speed_limit else 0.0
        else:
            e = merger_efficiency(diameter_j, diameter_k, dv, rho, density_slag, interfacial_tension, psi,
                                  virtual_mass, form, threshold, rule)
        b += 0.25 * math.pi * d_sum * d_sum * dv * e
    if shear_rate > 0.0:
        if tabulated:
            e = 1.0 if shear_speed <= speed_limit else 0.0
        else:
            e = merger_efficiency(diameter_j, diameter_k, shear_speed, rho, density_slag, interfacial_tension, psi,
                                  virtual_mass, form, threshold, rule)
        b += shear_rate * d_sum * d_sum * d_sum / 6.0 * e
    return b * efficiency


@njit(cache=True)
def collision_kernel(number, pivots, diameters, velocities, densities, shear_rate, density_slag,
                     interfacial_tension, psi, virtual_mass, form, threshold, rule, efficiency, speed_limit, target,
                     beta):
    """Coalescence kernel beta_jk [m^3/s] of one cell, every pair (:func:`pair_kernel`); beta (K, K) is written.

    diameters [m] and densities [kg/m^3] are the droplets' actual ones (after reaction), velocities [m/s] their
    settling velocities in this cell (hindered), shear_rate G [1/s]. speed_limit (K, K): :func:`merger_speed_limit`
    per pair for the 'step' rule with fixed sizes, or an empty (0, 0) array to evaluate Eq. 2 directly. Pairs whose
    merger would exceed the size limit (target < 0) get 0. number (K,) [1/m^3] and pivots (K,) [m^3]: pairs with a
    section below NEGLIGIBLE_VOLUME_FRACTION get 0 (far upwind tails; their mergers are nil and Eq. 2 is the costly
    part). The time loop uses :func:`collision_pairs`, which gives the same beta on the pairs it lists.
    """
    n_k = diameters.size
    tabulated = speed_limit.shape[0] == n_k
    for j in range(n_k):
        for k in range(j, n_k):
            b = 0.0
            if (target[j, k] >= 0 and number[j] * pivots[j] >= NEGLIGIBLE_VOLUME_FRACTION
                    and number[k] * pivots[k] >= NEGLIGIBLE_VOLUME_FRACTION):
                b = pair_kernel(diameters[j], diameters[k], velocities[j], velocities[k], densities[j], densities[k],
                                speed_limit[j, k] if tabulated else 0.0, tabulated, shear_rate, density_slag,
                                interfacial_tension, psi, virtual_mass, form, threshold, rule, efficiency)
            beta[j, k] = b
            beta[k, j] = b


@njit(cache=True)
def occupied_sections(number, pivots, sections):
    """Ascending indices of the sections with N_k x_k >= NEGLIGIBLE_VOLUME_FRACTION into sections (K,) int64;
    number (K,) [1/m^3], pivots (K,) [m^3]. Returns how many."""
    count = 0
    for k in range(number.size):
        if number[k] * pivots[k] >= NEGLIGIBLE_VOLUME_FRACTION:
            sections[count] = k
            count += 1
    return count


@njit(cache=True)
def collision_pairs(sections, count, diameters, velocities, densities, shear_rate, density_slag,
                    interfacial_tension, psi, virtual_mass, form, threshold, rule, efficiency, speed_limit, target,
                    beta, pair_j, pair_k, pair_target, pair_beta):
    """Kernel of one cell on its occupied sections, and the list of pairs that merge; returns the list's length.

    sections (K,) int64, count: the occupied sections (:func:`occupied_sections`). For every pair j <= k of them
    within the size limit, writes beta_jk = beta_kj (:func:`pair_kernel`; other entries of beta are left as they
    are and must not be read) and, where beta_jk > 0, appends (j, k, target, beta) to the pair arrays (P,), in the
    order of the full (j, k) loop. Other arguments as :func:`collision_kernel`.
    """
    tabulated = speed_limit.shape[0] == diameters.size
    pairs = 0
    for a in range(count):
        j = sections[a]
        for c in range(a, count):
            k = sections[c]
            i = target[j, k]
            if i < 0:
                break  # pivots increase with k, so every larger partner exceeds the limit too
            b = pair_kernel(diameters[j], diameters[k], velocities[j], velocities[k], densities[j], densities[k],
                            speed_limit[j, k] if tabulated else 0.0, tabulated, shear_rate, density_slag,
                            interfacial_tension, psi, virtual_mass, form, threshold, rule, efficiency)
            beta[j, k] = b
            beta[k, j] = b
            if b != 0.0:
                pair_j[pairs] = j
                pair_k[pairs] = k
                pair_target[pairs] = i
                pair_beta[pairs] = b
                pairs += 1
    return pairs


@njit(cache=True)
def busy_discount(number, diameters, growth_target, growth_rate, beta, pair_j, pair_k, pairs, pair_beta, free,
                  update, pair_load):
    """Discount a cell's kernel for partners that are busy: one merge at a time, each taking the pair's growth time.

    In the full engine a marked pair merges only after its growth time t_jk (settler.physics.growth_time, the
    engine's own law), neither partner can be marked again before, and only pairs of two free droplets are marked. A
    droplet of section j is therefore free a share f_j of the time with f_j = 1 / (1 + sum_k beta_jk N_k f_k t_jk):
    its merges per second with free partners times their duration (a handling time, as in Holling's type-II
    response; frozen over the step). The shares are solved by averaged substitution, f <- (f + 1 / (1 + L(f))) / 2,
    which contracts at least twofold per sweep (to 1e-12, at most MAX_BUSY_SWEEPS), and each listed pair's kernel
    becomes beta_jk f_j f_k, in ``pair_beta`` and in ``beta`` (K, K) alike. For one size in a dense cloud a droplet
    then merges (1 - f) / t times a second, at most once per growth time, as in the engine. number (K,) [1/m^3],
    diameters (K,) [m]; free and update (K,) and pair_load (P,) are work space (free ends holding the shares).
    """
    for p in range(pairs):  # beta_jk t_jk, once per pair rather than once per sweep
        pair_load[p] = pair_beta[p] * growth_time(diameters[pair_j[p]], diameters[pair_k[p]], growth_target,
                                                  growth_rate)
    free[:] = 1.0
    for _ in range(MAX_BUSY_SWEEPS):
        update[:] = 0.0
        for p in range(pairs):
            j, k = pair_j[p], pair_k[p]
            update[j] += pair_load[p] * number[k] * free[k]
            if k != j:
                update[k] += pair_load[p] * number[j] * free[j]
        change = 0.0
        for j in range(free.size):
            new = 0.5 * (free[j] + 1.0 / (1.0 + update[j]))
            change = max(change, abs(new - free[j]))
            free[j] = new
        if change <= 1e-12:
            break
    for p in range(pairs):
        j, k = pair_j[p], pair_k[p]
        b = pair_beta[p] * free[j] * free[k]
        pair_beta[p] = b
        beta[j, k] = b
        beta[k, j] = b


@njit(cache=True)
def coalesce_zone(content, diameters, velocities, densities, volume_fraction, shear_rate, pivots, target,
                  loss_weight, dt, density_slag, interfacial_tension, psi, virtual_mass, form, threshold, rule,
                  efficiency, speed_limit, max_rate_step, beta, births, k1, k2, trial, busy, growth_target,
                  growth_rate):
    """Coalescence in every occupied cell of one zone over dt [s]; returns the largest number of sub-steps.

    content (J, Q, K) in place; diameters, velocities, densities (J, K) and volume_fraction (J,) from
    :func:`cell_properties`; shear_rate (J,) [1/s]; speed_limit as in :func:`collision_kernel`; pivots, target,
    loss_weight from the grid. Cells below NEGLIGIBLE_VOLUME_FRACTION are skipped (the far tails the upwind scheme
    spreads ahead of a front, whose coalescence rate ~ phi^2 is nil). beta (K, K), births (Q + 1, K), k1, k2,
    trial (Q, K) are work space; the section and pair lists (K and K (K + 1) / 2 entries) are allocated once per
    call, outside the cell loop. ``busy`` (bool): discount the kernel for partners busy merging
    (:func:`busy_discount`, with the case's coalescence.growth_target [-] and growth_rate [1/s]; ignored when off).
    """
    n_k = pivots.size
    size = n_k * (n_k + 1) // 2
    free, update = np.empty(n_k), np.empty(n_k)
    sections = np.empty(n_k, np.int64)
    pair_j, pair_k, pair_target = np.empty(size, np.int64), np.empty(size, np.int64), np.empty(size, np.int64)
    pair_beta, pair_load = np.empty(size), np.empty(size)
    most = 0
    for j in range(content.shape[0]):
        if volume_fraction[j] < NEGLIGIBLE_VOLUME_FRACTION:
            continue
        count = occupied_sections(content[j, NUMBER], pivots, sections)
        pairs = collision_pairs(sections, count, diameters[j], velocities[j], densities[j], shear_rate[j],
                                density_slag, interfacial_tension, psi, virtual_mass, form, threshold, rule,
                                efficiency, speed_limit, target, beta, pair_j, pair_k, pair_target, pair_beta)
        if busy:
            busy_discount(content[j, NUMBER], diameters[j], growth_target, growth_rate, beta, pair_j, pair_k, pairs,
                          pair_beta, free, update, pair_load)
        steps = coalesce_cell(content[j], pivots, sections, count, target, loss_weight, beta, pair_j, pair_k,
                              pair_target, pair_beta, pairs, dt, max_rate_step, births, k1, k2, trial)
        most = max(most, steps)
    return most


# ------------------------------------------------------------------------------------------ droplet properties
@njit(cache=True)
def composition_age(fes_removed, original_diameter, x_initial, x_final, time_constant):
    """Age [s] at which a droplet fed at X0 with original diameter d0 [m] has lost ``fes_removed`` [kg] of FeS.

    Inverse of settler.physics.reacted_mass through the shared laws (species_masses, composition_from_masses,
    reaction_age); capped at AGE_CAP_TIME_CONSTANTS time constants, where the fit has reached its end state.
    """
    mass_cu2s, mass_fes = species_masses(original_diameter, x_initial)
    x = composition_from_masses(mass_cu2s, max(mass_fes - fes_removed, 0.0))
    cap = AGE_CAP_TIME_CONSTANTS * time_constant
    if x >= x_final:
        return cap
    return min(max(reaction_age(x, x_initial, x_final, time_constant), 0.0), cap)


@njit(cache=True)
def table_velocity(row, age, age_step):
    """Linear interpolation of a settling-velocity table row over age (one entry: age-independent) [m/s]."""
    if row.size == 1:
        return row[0]
    s = age / age_step
    m = int(s)
    if m >= row.size - 1:
        return row[row.size - 1]
    f = s - m
    return (1.0 - f) * row[m] + f * row[m + 1]


@njit(cache=True)
def cell_properties(content, pivots, original_diameters, reacting, x_initial, x_final, time_constant,
                    velocity_table, age_step, hindered_exponent, density_feed, density_slag, viscosity, gravity,
                    cloud_coefficient, cloud_radius, downflow, diameters, densities, velocities,
                    volume_fraction, collective_velocity):
    """Per-cell droplet properties of one zone, evaluated at the start of a step.

    content (J, Q, K). For each section: age (composition age with reaction, else the volume-weighted mean age),
    actual diameter d0 * relative_diameter_at_age and density_at_age (shared fit), single-droplet settling
    velocity from the table, hindered by richardson_zaki_factor of the cell's matte volume fraction, plus the
    zone's collective (channel) velocity and the slag downflow at the cell's lower face.

    Channel closure (derivation in popbal.closures): u_c = c_j g R_j^2 sum_k phi_k (rho_k - rho_slag) / mu with the
    cell's cloud coefficient c_j = cloud_coefficient[j] [-] and length scale R_j = cloud_radius[j] [m] (J,): the
    Hadamard-Rybczynski velocity of a cloud of excess density phi (rho - rho_slag) when c = 4/15 and R = R_c; in
    the feed layer under the inlet c and R are the layer's (popbal.closures.cloud_profile); zero where the
    coefficient or the radius is 0 (the outer zone).

    Outputs (filled): diameters, densities, velocities (J, K) [m, kg/m^3, m/s downwards]; volume_fraction and
    collective_velocity (J,) [-, m/s]. Empty sections take the age of the same section in the cell above (age 0 at
    the top), so a lagged velocity exists for droplets arriving during the step.
    """
    n_j, _, n_k = content.shape
    for k in range(n_k):
        age = 0.0
        for j in range(n_j - 1, -1, -1):
            n = content[j, NUMBER, k]
            if n * pivots[k] > 0.0:  # not empty, nor so sparse that the volume underflows
                if reacting:
                    age = composition_age(content[j, FES_REMOVED, k] / n, original_diameters[k], x_initial,
                                          x_final, time_constant)
                else:
                    age = content[j, AGE, k] / (n * pivots[k])
            if reacting:
                diameters[j, k] = original_diameters[k] * relative_diameter_at_age(age, x_initial, x_final,
                                                                                   time_constant)
                densities[j, k] = density_at_age(age, x_initial, x_final, time_constant)
            else:
                diameters[j, k] = original_diameters[k]
                densities[j, k] = density_feed
            velocities[j, k] = table_velocity(velocity_table[k], age, age_step)
    for j in range(n_j):
        phi = 0.0
        excess = 0.0
        for k in range(n_k):
            d = diameters[j, k]
            phi_k = content[j, NUMBER, k] * math.pi / 6.0 * d * d * d
            phi += phi_k
            excess += phi_k * (densities[j, k] - density_slag)
        volume_fraction[j] = phi
        u_c = cloud_velocity(excess, cloud_radius[j], viscosity, cloud_coefficient[j], gravity)
        collective_velocity[j] = u_c
        hindrance = richardson_zaki_factor(min(phi, 1.0), hindered_exponent)
        for k in range(n_k):
            velocities[j, k] = velocities[j, k] * hindrance + u_c + downflow[j]


# --------------------------------------------------------------------------------------------------- transport
@njit(cache=True)
def transport_zone(content, face_velocity, sink_rate, top_source, dz, dt, bottom_out, sink_out):
    """Implicit (backward-Euler) first-order upwind transport in z of one zone over dt [s].

    content (J, Q, K), cell 0 at the bottom. face_velocity (J, K) [m/s, >= 0 downwards]: velocity of section k's
    droplets through the lower face of cell j (upwind: the droplets of cell j cross it). sink_rate (J,) [1/s]:
    volumetric slag withdrawal per unit volume (side outlet band). top_source (Q, K): feed into the top cell [per
    m^3 per s]. Every velocity points down, so the implicit system is lower-triangular and solved in one sweep from
    the top: unconditionally stable and positive, and conservative -- what leaves a cell enters the one below.
    bottom_out and sink_out (Q, K) accumulate what left through the bottom and through the sink during dt, per unit
    area of the zone [per m^2].
    """
    n_j, n_q, n_k = content.shape
    for k in range(n_k):
        for q in range(n_q):
            inflow = dt * top_source[q, k]
            for j in range(n_j - 1, -1, -1):
                courant = dt * face_velocity[j, k] / dz
                withdrawn = dt * sink_rate[j]
                new = (content[j, q, k] + inflow) / (1.0 + courant + withdrawn)
                content[j, q, k] = new
                sink_out[q, k] += withdrawn * new * dz
                inflow = courant * new
            bottom_out[q, k] += inflow * dz


@njit(cache=True)
def transport_two_way(content, velocity, sink_rate, top_source, bottom_source, dz, dt, bottom_out, top_out,
                      sink_out, diagonal, upper, rhs, loss_rate, lateral_out, diffusivity):
    """Implicit (backward-Euler) first-order donor-cell transport in z of one zone over dt [s], for velocities of
    either sign: the return-flow zone, where droplets slower than the slag's upflow rise.

    content (J, Q, K), cell 0 at the bottom. velocity (J, K) [m/s, > 0 downwards]: the velocity of section k's
    droplets in cell j; a cell passes v+ c / dz per second to the cell below (v > 0) or |v| c / dz to the cell above
    (v < 0), so each row of the implicit system is (1 + |v_j| dt/dz + s_j dt) c_j - v+_{j+1} dt/dz c_{j+1}
    - v-_{j-1} dt/dz c_{j-1} = c_j^old + sources dt: a diagonally dominant tridiagonal M-matrix, solved by the Thomas
    algorithm (stable, positive, conservative). top_source, bottom_source (Q, K): sources into the top and bottom
    cells [per m^3 per s]. bottom_out, top_out, sink_out (Q, K) accumulate what left through the bottom (downward
    droplets of cell 0), the top (rising droplets of the top cell) and the sink during dt, per m^2 of the zone.
    loss_rate (J,) [1/s, >= 0]: a sideways loss like the sink's (the plume's entrainment of the return flow,
    popbal.closures.exchange_rates; zeros: none), accumulated per cell into lateral_out (J, Q, K) [per m^3 of the
    zone]. diffusivity D [m^2/s, >= 0]: an eddy diffusivity spreading every section over the height (the
    stirring of the box-wide circulation, popbal.outer_dispersion): each face passes D (c_j - c_{j+1}) / dz^2 per
    second between its cells, none through the top and the bottom, adding d = D dt / dz^2 to both off-diagonals and
    to the diagonal once per neighbour (still an M-matrix; conservative). diagonal, upper, rhs (J,): work space.
    With every velocity >= 0, no bottom source and D = 0 it gives :func:`transport_zone`'s result (the same
    lower-triangular system).
    """
    n_j, n_q, n_k = content.shape
    c = dt / dz
    d = diffusivity * dt / (dz * dz)
    for k in range(n_k):
        for q in range(n_q):
            # build: lower_j = -c v-_{j-1} - d, diagonal_j, upper_j = -c v+_{j+1} - d; forward elimination
            for j in range(n_j):
                v = velocity[j, k]
                neighbours = (1.0 if j > 0 else 0.0) + (1.0 if j + 1 < n_j else 0.0)
                diagonal[j] = 1.0 + c * abs(v) + dt * sink_rate[j] + dt * loss_rate[j] + d * neighbours
                upper[j] = -c * max(velocity[j + 1, k], 0.0) - d if j + 1 < n_j else 0.0
                rhs[j] = content[j, q, k]
            rhs[n_j - 1] += dt * top_source[q, k]
            rhs[0] += dt * bottom_source[q, k]
            for j in range(1, n_j):
                lower = -c * max(-velocity[j - 1, k], 0.0) - d
                if lower != 0.0:
                    factor = lower / diagonal[j - 1]
                    diagonal[j] -= factor * upper[j - 1]
                    rhs[j] -= factor * rhs[j - 1]
            new = rhs[n_j - 1] / diagonal[n_j - 1]
            content[n_j - 1, q, k] = new
            for j in range(n_j - 2, -1, -1):
                new = (rhs[j] - upper[j] * content[j + 1, q, k]) / diagonal[j]
                content[j, q, k] = new
            for j in range(n_j):
                sink_out[q, k] += dt * sink_rate[j] * content[j, q, k] * dz
                lateral_out[j, q, k] += dt * loss_rate[j] * content[j, q, k]
            bottom_out[q, k] += dt * max(velocity[0, k], 0.0) * content[0, q, k]
            top_out[q, k] += dt * max(-velocity[n_j - 1, k], 0.0) * content[n_j - 1, q, k]


# ---------------------------------------------------------------------------------------------------- reaction
@njit(cache=True)
def react_zone(content, pivots, original_diameters, reacting, x_initial, x_final, time_constant, dt):
    """Age every droplet of one zone by dt [s]; with reaction, remove FeS along the shared fit.

    The age moment grows by N x_k dt. With reaction, a section at composition age a (from its FES_REMOVED per
    droplet) goes to reacted_mass(d0, a + dt) per droplet -- the fit itself, not a rate, so the step adds no
    integration error. Returns the increase of FES_REMOVED summed over cells and sections [kg/m^3]; times dz and
    the zone area it is the FeS mass removed during dt [kg].
    """
    removed = 0.0
    n_j, _, n_k = content.shape
    for j in range(n_j):
        for k in range(n_k):
            n = content[j, NUMBER, k]
            if n <= 0.0:
                continue
            content[j, AGE, k] += n * pivots[k] * dt
            if reacting:
                per_droplet = content[j, FES_REMOVED, k] / n
                age = composition_age(per_droplet, original_diameters[k], x_initial, x_final, time_constant)
                new = reacted_mass(original_diameters[k], age + dt, x_initial, x_final, time_constant)
                if new > per_droplet:
                    content[j, FES_REMOVED, k] = n * new
                    removed += n * (new - per_droplet)
    return removed
