"""Busy partners (popbal.busy_partners): popbal's kernel discounted for droplets that merge one partner at a time,
each merge taking the full engine's growth time, as the delayed coalescence of fulldem does.

Checked against closed forms: the growth time of equal and of very unequal partners; a collector in a cloud of
small droplets merges at beta N f_c f_s per second, which for a dense cloud tends to one merge per growth time (the
full engine's cap: a marked droplet cannot be marked again before it merges); without load nothing changes; and the
option, off, leaves a popbal run exactly as it was."""

import math

import numpy as np
import pytest

from popbal.kernels import busy_discount, growth_time

TARGET, RATE = 0.95, 2.0  # coalescence.growth_target [-] and growth_rate [1/s] of data/properties/flash_smelting.toml


def test_growth_time_of_equal_and_unequal_partners():
    d = 1e-3
    merged = 2.0 ** (1.0 / 3.0) * d
    assert growth_time(d, d, TARGET, RATE) == pytest.approx((TARGET * merged - d) / (RATE * merged), rel=1e-14)
    assert growth_time(d, d, TARGET, RATE) == pytest.approx(0.0781, abs=1e-4)
    # a fine partner of a collector: its contact diameter grows from ~0 to 0.95 of the collector's
    assert growth_time(5e-3, 0.05e-3, TARGET, RATE) == pytest.approx((TARGET - 0.01) / RATE, rel=1e-5)
    # partners already past the target (a growth_target below d_small / d_m) wait no time
    assert growth_time(d, d, 0.5, RATE) == 0.0


def _collector_cell(beta_cs, n_small, n_coll=1.0, beta_ss=0.0):
    """Sections 0 (small, 0.5 mm) and 1 (collector, 5 mm): the pair list as collision_pairs gives it."""
    diameters = np.array([0.5e-3, 5e-3])
    number = np.array([n_small, n_coll])
    beta = np.zeros((2, 2))
    pair_j, pair_k = np.array([0, 0], np.int64), np.array([0, 1], np.int64)
    pair_beta = np.array([beta_ss, beta_cs])
    beta[0, 1] = beta[1, 0] = beta_cs
    beta[0, 0] = beta_ss
    busy_discount(number, diameters, TARGET, RATE, beta, pair_j, pair_k, 2, pair_beta, np.empty(2))
    return diameters, pair_beta, beta


@pytest.mark.parametrize("n_small", [1e3, 1e6, 1e8, 1e10])
def test_a_collector_merges_at_most_once_per_growth_time(n_small):
    beta_cs = 2e-6  # m^3/s: a 5 mm collector falling 0.1 m/s through 0.5 mm droplets (pi/4 (5.5 mm)^2 x 0.1 m/s)
    diameters, pair_beta, beta = _collector_cell(beta_cs, n_small)
    t = growth_time(diameters[0], diameters[1], TARGET, RATE)
    # the collector's load beta N t; the small droplets' load from one collector per m^3 is negligible
    free_collector = 1.0 / (1.0 + beta_cs * n_small * t)
    free_small = 1.0 / (1.0 + beta_cs * 1.0 * t)
    assert pair_beta[1] == pytest.approx(beta_cs * free_collector * free_small, rel=1e-12)
    assert beta[0, 1] == beta[1, 0] == pair_beta[1]
    rate = pair_beta[1] * n_small  # merges per second of one collector
    assert rate == pytest.approx(beta_cs * n_small / (1.0 + beta_cs * n_small * t), rel=1e-5)
    assert rate < 1.0 / t
    if beta_cs * n_small * t > 1e3:
        assert rate == pytest.approx(1.0 / t, rel=2e-3)


def test_without_load_the_kernel_is_unchanged():
    _, pair_beta, _ = _collector_cell(1e-12, 1.0)
    assert pair_beta[1] == pytest.approx(1e-12, rel=1e-11)


def test_a_section_merging_with_itself_counts_its_own_partners():
    # equal droplets only: f = 1 / (1 + beta N t), both partners from the same section
    n, b = 1e8, 1e-8
    diameters = np.array([1e-3])
    beta = np.array([[b]])
    pair_beta = np.array([b])
    busy_discount(np.array([n]), diameters, TARGET, RATE, beta, np.array([0], np.int64), np.array([0], np.int64), 1,
                  pair_beta, np.empty(1))
    t = growth_time(1e-3, 1e-3, TARGET, RATE)
    assert pair_beta[0] == pytest.approx(b / (1.0 + b * n * t) ** 2, rel=1e-12)
    assert math.isclose(beta[0, 0], pair_beta[0])


def test_off_leaves_a_run_as_it_was():
    import popbal
    from settler.cases import load_case

    quick = {"popbal.end_time": 2.0, "popbal.output_interval": 1.0, "popbal.height_cells": 10,
             "popbal.sections_per_doubling": 1, "popbal.time_step": 0.1}
    plain = popbal.run(load_case("simple", quick), progress=False)
    off = popbal.run(load_case("simple", {**quick, "popbal.busy_partners": False}), progress=False)
    on = popbal.run(load_case("simple", {**quick, "popbal.busy_partners": True}), progress=False)
    columns = ["droplet_count", "mean_diameter", "mass_settled"]
    assert plain.timeseries[columns].equals(off.timeseries[columns])
    # on: fewer merges, so more droplets; matte is conserved either way
    assert on.timeseries["droplet_count"].iloc[-1] > plain.timeseries["droplet_count"].iloc[-1]
    for result in (plain, on):
        assert np.nanmax(np.abs(result.timeseries["mass_balance_error"])) < 1e-10
