"""Busy partners (popbal.busy_partners): popbal's kernel discounted for droplets that merge one partner at a time,
each merge taking the full engine's growth time, as the delayed coalescence of fulldem does (a pair is marked only
when both droplets are free, and neither is marked again before it merges).

Checked against closed forms: the growth time of equal and of very unequal partners; one size in a cloud, where the
free share solves f = 1 / (1 + A f), A = beta N t, so f = (sqrt(1 + 4A) - 1) / (2A) and a droplet merges (1 - f) / t
times a second, tending to once per growth time; a rare collector in a cloud of small droplets, whose merge rate
tends to 1 / t; no load, no change; and a popbal run with the option on merges less and still conserves matte."""

import numpy as np
import pytest

from popbal.kernels import busy_discount
from settler.physics import growth_time

TARGET, RATE = 0.95, 2.0  # coalescence.growth_target [-] and growth_rate [1/s] of data/properties/flash_smelting.toml


def test_growth_time_of_equal_and_unequal_partners():
    d = 1e-3
    merged = 2.0 ** (1.0 / 3.0) * d
    assert growth_time(d, d, TARGET, RATE) == pytest.approx((TARGET * merged - d) / (RATE * merged), rel=1e-14)
    assert growth_time(d, d, TARGET, RATE) == pytest.approx(0.0781, abs=1e-4)
    # a fine partner of a collector: its contact diameter grows from 1 % to 95 % of the collector's
    assert growth_time(5e-3, 0.05e-3, TARGET, RATE) == pytest.approx((TARGET - 0.01) / RATE, rel=1e-5)
    # partners already past the target (a growth_target below d_small / d_m) wait no time
    assert growth_time(d, d, 0.5, RATE) == 0.0


def _discount(number, diameters, pairs):
    """busy_discount on sections ``diameters`` [m] with numbers ``number`` [1/m^3] and pairs {(j, k): beta}."""
    n = len(diameters)
    beta = np.zeros((n, n))
    keys = sorted(pairs)
    pair_j = np.array([j for j, _ in keys], np.int64)
    pair_k = np.array([k for _, k in keys], np.int64)
    pair_beta = np.array([pairs[key] for key in keys])
    free = np.empty(n)
    busy_discount(np.asarray(number, float), np.asarray(diameters, float), TARGET, RATE, beta, pair_j, pair_k,
                  len(keys), pair_beta, free, np.empty(n), np.empty(len(keys)))
    return dict(zip(keys, pair_beta)), beta, free


@pytest.mark.parametrize("load", [1e-3, 0.3, 1.0, 3.0, 10.0, 100.0, 1e4])
def test_one_size_merges_at_most_once_per_growth_time(load):
    d = 1e-3
    t = growth_time(d, d, TARGET, RATE)
    b = 1e-8
    n = load / (b * t)
    discounted, beta, free = _discount([n], [d], {(0, 0): b})
    exact = (np.sqrt(1.0 + 4.0 * load) - 1.0) / (2.0 * load)
    assert free[0] == pytest.approx(exact, rel=1e-10)
    assert discounted[(0, 0)] == pytest.approx(b * exact**2, rel=1e-9) and beta[0, 0] == discounted[(0, 0)]
    rate = discounted[(0, 0)] * n  # merges per second of one droplet (pair_rates halves the pairs, each has two)
    assert rate == pytest.approx((1.0 - exact) / t, rel=1e-9)
    assert rate < 1.0 / t
    if load >= 1e4:
        assert rate == pytest.approx(1.0 / t, rel=0.011)


@pytest.mark.parametrize("n_small", [1e3, 1e6, 1e8, 1e10])
def test_a_rare_collector_merges_at_most_once_per_growth_time(n_small):
    beta_cs = 2e-6  # m^3/s: a 5 mm collector falling 0.1 m/s through 0.5 mm droplets (pi/4 (5.5 mm)^2 x 0.1 m/s)
    diameters = [0.5e-3, 5e-3]
    discounted, beta, free = _discount([n_small, 1.0], diameters, {(0, 1): beta_cs})
    t = growth_time(*diameters, TARGET, RATE)
    # one collector per m^3 keeps the small droplets free; the collector solves f = 1 / (1 + beta N f_s t)
    assert free[0] == pytest.approx(1.0, abs=1e-5)
    assert free[1] == pytest.approx(1.0 / (1.0 + beta_cs * n_small * free[0] * t), rel=1e-10)
    rate = discounted[(0, 1)] * n_small  # merges per second of the collector
    assert beta[0, 1] == beta[1, 0] == discounted[(0, 1)]
    assert rate == pytest.approx(beta_cs * n_small / (1.0 + beta_cs * n_small * t), rel=1e-4)
    assert rate < 1.0 / t
    if beta_cs * n_small * t > 1e3:
        assert rate == pytest.approx(1.0 / t, rel=2e-3)


def test_without_load_the_kernel_is_unchanged():
    discounted, _, free = _discount([1.0, 1.0], [0.5e-3, 5e-3], {(0, 1): 1e-12})
    assert discounted[(0, 1)] == pytest.approx(1e-12, rel=1e-11) and free == pytest.approx(1.0, abs=1e-11)


def test_a_run_with_busy_partners_merges_less_and_conserves_matte():
    import popbal
    from settler.cases import load_case

    quick = {"popbal.end_time": 2.0, "popbal.output_interval": 1.0, "popbal.height_cells": 10,
             "popbal.sections_per_doubling": 1, "popbal.time_step": 0.1}
    plain = popbal.run(load_case("simple", quick), progress=False)
    on = popbal.run(load_case("simple", {**quick, "popbal.busy_partners": True}), progress=False)
    assert on.model.parameters["busy_partners"] and not plain.model.parameters["busy_partners"]
    assert on.timeseries["droplet_count"].iloc[-1] > plain.timeseries["droplet_count"].iloc[-1]
    for result in (plain, on):
        assert np.nanmax(np.abs(result.timeseries["mass_balance_error"])) < 1e-10


def test_the_busy_closures_switch_it_on_in_the_fit_and_in_the_written_layer():
    from analysis.calibration.hierarchy import CLOSURES

    assert CLOSURES["busy"]["switches"] == {"popbal.busy_partners": True}
    assert CLOSURES["busy"]["levels"] == CLOSURES["designed"]["levels"]
    assert CLOSURES["layers_busy"]["switches"] == CLOSURES["busy"]["switches"]
    assert CLOSURES["layers_busy"]["levels"] == CLOSURES["layers"]["levels"] and CLOSURES["layers_busy"]["layers"]
    assert "switches" not in CLOSURES["designed"] and "switches" not in CLOSURES["layers"]


def test_the_command_line_offers_every_closure_set():
    from analysis.calibrate import CLOSURE_NAMES
    from analysis.calibration.hierarchy import CLOSURES

    assert set(CLOSURE_NAMES) == set(CLOSURES)
