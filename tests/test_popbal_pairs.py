"""popbal's pair-list coalescence (the time loop's fast path) against the full pair loops and NumPy twins, and the
time-series-only save a sweep's points use.

The fast path lists, per cell, the pairs of occupied sections that can merge (collision_pairs) and visits only those
in every sub-step (pair_rates, largest_death_rate). Skipped pairs contribute exact zeros and the list keeps the order
of the full loop, so the claim is bit-identity with the full loops, checked here with array_equal; the full loops
are in turn checked against the plain-NumPy twins (tests/test_popbal_kernels.py), and coalesce_zone against a NumPy
Heun integration built on the twins (tolerance 1e-12 relative, round-off of a few hundred operations).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import popbal
from analysis import load_run
from analysis import sweep as sw
from popbal import reference
from popbal.grid import make_grid, volume_of
from popbal.kernels import (AGE, FES_REMOVED, NEGLIGIBLE_VOLUME_FRACTION, NUMBER, QUANTITIES, RULE_PROBABILITY,
                            RULE_STEP, carried_rows, cell_average_rates, coalesce_zone, collision_kernel,
                            collision_pairs, largest_death_rate, merger_speed_limit, occupied_sections, pair_rates)
from settler.physics import FORM_LUO, FORM_SEED

#: The simple-case point of tests/test_analysis_sweep.py that runs in milliseconds.
TINY = {"popbal.end_time": 1.0, "popbal.output_interval": 0.5, "popbal.height_cells": 10,
        "popbal.sections_per_doubling": 1, "popbal.time_step": 0.1}
#: density_slag, interfacial_tension [N/m], psi, virtual_mass, threshold, efficiency: plausible matte/slag values.
SLAG, SIGMA, PSI, VIRTUAL, THRESHOLD, EFFICIENCY = 3150.0, 0.01, 1.0, 0.5, 0.5, 0.7


@pytest.fixture
def grid():
    return make_grid(volume_of(50e-6), volume_of(2e-3), 2)


def _cell(rng, grid, fes=True):
    """(Q, K) content with empty sections, sections below NEGLIGIBLE_VOLUME_FRACTION and a gap in the middle."""
    content = np.zeros((QUANTITIES, grid.size))
    number = rng.uniform(1e2, 1e9, grid.size) * (rng.random(grid.size) < 0.75)
    number[grid.size // 2] = 0.0
    number[2] = 0.1 * NEGLIGIBLE_VOLUME_FRACTION / grid.pivots[2]  # present but negligible: no kernel, no list
    content[NUMBER] = number
    content[AGE] = number * grid.pivots * rng.uniform(0.0, 50.0, grid.size)
    if fes:
        content[FES_REMOVED] = number * grid.pivots * rng.uniform(0.0, 100.0, grid.size)
    return content


def _properties(rng, grid):
    d = grid.diameters * rng.uniform(0.9, 1.0, grid.size)
    v = np.sort(rng.uniform(1e-5, 1e-2, grid.size))
    rho = rng.uniform(4500.0, 5200.0, grid.size)
    return d, v, rho


def _speed_table(grid, rho):
    return np.array([[merger_speed_limit(a, b, rho, SLAG, SIGMA, PSI, VIRTUAL, FORM_SEED, THRESHOLD)
                      for b in grid.diameters] for a in grid.diameters])


def _lists(grid, content, d, v, rho, shear, form, rule, limit):
    """beta (K, K) from collision_pairs (NaN where it must not be read) and the pair list it makes."""
    k = grid.size
    sections = np.empty(k, np.int64)
    count = occupied_sections(content[NUMBER], grid.pivots, sections)
    size = k * (k + 1) // 2
    pair_j, pair_k, pair_target = (np.empty(size, np.int64) for _ in range(3))
    pair_beta = np.empty(size)
    beta = np.full((k, k), np.nan)
    pairs = collision_pairs(sections, count, d, v, rho, shear, SLAG, SIGMA, PSI, VIRTUAL, form, THRESHOLD, rule,
                            EFFICIENCY, limit, grid.target, beta, pair_j, pair_k, pair_target, pair_beta)
    return sections, count, beta, (pair_j, pair_k, pair_target, pair_beta, pairs)


CASES = [(RULE_STEP, FORM_SEED, 1.3, True), (RULE_STEP, FORM_SEED, 0.0, False),
         (RULE_PROBABILITY, FORM_LUO, 0.0, False), (RULE_PROBABILITY, FORM_SEED, 50.0, False)]


@pytest.mark.parametrize("rule, form, shear, tabulated", CASES)
def test_pair_list_gives_the_full_loops_bit_for_bit(grid, rule, form, shear, tabulated):
    rng = np.random.default_rng(7)
    births = np.zeros((QUANTITIES + 1, grid.size))
    full, fast = np.zeros((QUANTITIES, grid.size)), np.zeros((QUANTITIES, grid.size))
    for _ in range(4):
        content = _cell(rng, grid)
        d, v, rho = _properties(rng, grid)
        limit = _speed_table(grid, 4800.0) if tabulated else np.empty((0, 0))
        beta_full = np.zeros((grid.size, grid.size))
        collision_kernel(content[NUMBER], grid.pivots, d, v, rho, shear, SLAG, SIGMA, PSI, VIRTUAL, form, THRESHOLD,
                         rule, EFFICIENCY, limit, grid.target, beta_full)
        sections, count, beta, pairs = _lists(grid, content, d, v, rho, shear, form, rule, limit)
        occupied = content[NUMBER] * grid.pivots >= NEGLIGIBLE_VOLUME_FRACTION
        assert np.array_equal(sections[:count], np.flatnonzero(occupied))
        # the entries collision_pairs writes are the full kernel's, and it lists exactly the full kernel's mergers
        within = np.outer(occupied, occupied) & (grid.target >= 0)
        assert np.array_equal(beta[within], beta_full[within])
        listed = {(j, k) for j, k in zip(pairs[0][:pairs[4]], pairs[1][:pairs[4]])}
        assert listed == {(j, k) for j, k in zip(*np.nonzero(np.triu(beta_full) > 0.0))}
        assert np.all(np.diff(pairs[0][:pairs[4]] * grid.size + pairs[1][:pairs[4]]) > 0)  # (j, k) order
        cell_average_rates(content, grid.pivots, grid.target, beta_full, births, full)
        pair_rates(content, grid.pivots, *pairs, QUANTITIES, births, fast)
        assert np.array_equal(fast, full)
        twin = reference.cell_average_rates(content, grid.pivots, grid.target, beta_full)
        assert np.allclose(fast, twin, rtol=1e-12, atol=1e-12 * np.abs(twin).max())
        # the fastest death rate from the occupied sections only, against the formula on the full kernel
        expected = np.max(np.where(grid.target >= 0, beta_full * content[NUMBER] * grid.loss_weight, 0.0).sum(axis=1))
        rate = largest_death_rate(content, sections, count, grid.target, beta, grid.loss_weight)
        assert rate == pytest.approx(expected, rel=1e-13)


def test_zero_trailing_rows_are_skipped_without_changing_the_rates(grid):
    rng = np.random.default_rng(8)
    content = _cell(rng, grid, fes=False)
    assert carried_rows(content) == FES_REMOVED
    assert carried_rows(np.zeros((QUANTITIES, grid.size))) == 1
    d, v, rho = _properties(rng, grid)
    _, _, _, pairs = _lists(grid, content, d, v, rho, 0.0, FORM_SEED, RULE_STEP, _speed_table(grid, 4800.0))
    births = np.zeros((QUANTITIES + 1, grid.size))
    every, skipped = np.zeros((QUANTITIES, grid.size)), np.full((QUANTITIES, grid.size), np.nan)
    pair_rates(content, grid.pivots, *pairs, QUANTITIES, births, every)
    pair_rates(content, grid.pivots, *pairs, FES_REMOVED, births, skipped)
    assert np.array_equal(skipped, every) and np.all(every[FES_REMOVED] == 0.0)


def _numpy_coalesce(content, grid, beta, dt, max_rate_step):
    """One cell over dt with Heun sub-steps on the NumPy twin's rates (the scheme of popbal.kernels.coalesce_cell)."""
    rate = np.max(np.where(grid.target >= 0, beta * content[NUMBER] * grid.loss_weight, 0.0).sum(axis=1))
    steps = max(1, int(np.ceil(dt * rate / max_rate_step)))
    h = dt / steps
    for _ in range(steps):
        k1 = reference.cell_average_rates(content, grid.pivots, grid.target, beta)
        k2 = reference.cell_average_rates(content + h * k1, grid.pivots, grid.target, beta)
        content = content + 0.5 * h * (k1 + k2)
    return content, steps


def test_coalesce_zone_matches_a_numpy_heun_integration_and_conserves(grid):
    rng = np.random.default_rng(9)
    cells = 5
    content = np.stack([_cell(rng, grid) for _ in range(cells)])
    content *= rng.uniform(1e-4, 1e-2, (cells, 1, 1)) / (content[:, NUMBER] @ grid.pivots)[:, None, None]  # phi
    content[3] = 0.0  # an empty cell: skipped
    d, v, rho = _properties(rng, grid)
    diameters, densities = np.tile(d, (cells, 1)), np.tile(rho, (cells, 1))
    velocities = np.tile(v, (cells, 1)) * rng.uniform(0.5, 1.0, (cells, 1))
    volume_fraction = (content[:, NUMBER] * np.pi / 6.0 * diameters**3).sum(axis=1)
    shear = rng.uniform(0.0, 5.0, cells)
    betas = []
    for j in range(cells):
        beta = np.zeros((grid.size, grid.size))
        collision_kernel(content[j, NUMBER], grid.pivots, d, velocities[j], rho, shear[j], SLAG, SIGMA, PSI, VIRTUAL,
                         FORM_SEED, THRESHOLD, RULE_PROBABILITY, EFFICIENCY, np.empty((0, 0)), grid.target, beta)
        betas.append(beta)
    fastest = max(np.max(np.where(grid.target >= 0, b * c[NUMBER] * grid.loss_weight, 0.0).sum(axis=1))
                  for b, c in zip(betas, content))
    max_rate_step = 0.5
    dt = 6.0 * max_rate_step / fastest  # several sub-steps in the densest cell
    expected, most = [], 0
    for j in range(cells):
        if volume_fraction[j] < NEGLIGIBLE_VOLUME_FRACTION:
            expected.append(content[j])
            continue
        new, steps = _numpy_coalesce(content[j], grid, betas[j], dt, max_rate_step)
        expected.append(new)
        most = max(most, steps)
    volume_before = content[:, NUMBER] @ grid.pivots
    carried_before = content[:, AGE:].sum(axis=2)
    work = [np.zeros((grid.size, grid.size)), np.zeros((QUANTITIES + 1, grid.size))] + \
        [np.zeros((QUANTITIES, grid.size)) for _ in range(3)]
    steps = coalesce_zone(content, diameters, velocities, densities, volume_fraction, shear, grid.pivots, grid.target,
                          grid.loss_weight, dt, SLAG, SIGMA, PSI, VIRTUAL, FORM_SEED, THRESHOLD, RULE_PROBABILITY,
                          EFFICIENCY, np.empty((0, 0)), max_rate_step, *work, False, 0.95, 2.0)
    assert most > 1 and steps == most  # sub-stepped, and the same sub-steps as the NumPy scheme
    expected = np.stack(expected)
    assert np.allclose(content, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
    assert np.all(content[3] == 0.0)
    # mergers conserve volume and the carried quantities cell by cell
    assert np.allclose(content[:, NUMBER] @ grid.pivots, volume_before, rtol=1e-13)
    assert np.allclose(content[:, AGE:].sum(axis=2), carried_before, rtol=1e-13)


# ------------------------------------------------------------------------------------------- time-series-only save
def test_save_without_distribution_writes_the_same_time_series_and_no_npz(tmp_path):
    result = popbal.run(popbal.setup("simple", TINY), progress=False)
    full = result.save(tmp_path / "full")
    light = tmp_path / "light"
    light.mkdir()
    (light / "distribution.npz").write_bytes(b"an earlier run's")
    result.save(light, distribution=False)
    assert (full / "distribution.npz").is_file() and not (light / "distribution.npz").exists()
    assert (light / "timeseries.csv").read_bytes() == (full / "timeseries.csv").read_bytes()
    assert "distribution_arrays" not in json.loads((light / "metadata.json").read_text())
    assert "distribution_arrays" in json.loads((full / "metadata.json").read_text())
    run = load_run(light)  # still a popbal run, told by its metadata
    assert run.engine == "popbal" and len(run.timeseries) == len(result.timeseries)


def test_sweep_points_save_the_distribution_only_when_asked(tmp_path):
    case = popbal.setup("simple", TINY).case.to_dict()
    plain = sw.run_point(case, str(tmp_path / "plain"))
    asked = sw.run_point(case, str(tmp_path / "asked"), distribution=True)
    assert plain["status"] == asked["status"] == "done"
    assert plain["matte_loss"] == asked["matte_loss"] and plain["mean_diameter"] == asked["mean_diameter"]
    assert not (tmp_path / "plain" / "distribution.npz").exists()
    assert (tmp_path / "asked" / "distribution.npz").is_file()
