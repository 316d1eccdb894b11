"""popbal's 'flux' channel closure (popbal.closures, issue 13): the radius carries the feed at the plume volume
fraction 1 / k_R^2 (continuity), scales as Q^(1/4) and not with the inlet, and a run's steady axis velocity is the
analytic plume velocity u_s = sqrt(c Q drho g / (pi mu)) whether or not the droplets ride it at a reduced speed."""

from __future__ import annotations

import math

import numpy as np
import pytest

import popbal
from popbal import closures
from popbal.model import channel_closure
from settler.cases import load_case
from settler.physics import STANDARD_GRAVITY

#: The simple case's feed: Q = 0.0086 / 5100 m^3/s, drho = 1950 kg/m^3, mu = 0.45 Pa s, rho_s = 3150 kg/m^3.
Q, DRHO, MU, RHO_S = 0.0086 / 5100.0, 1950.0, 0.45, 3150.0


def test_flux_radius_holds_the_feed_at_the_plume_fraction():
    """pi R^2 u phi = Q with phi = 1 / k_R^2 to round-off, and R ~ Q^(1/4) (u ~ Q^(1/2)) for a 57-fold feed range."""
    c, k = 0.37, 5.0
    for q in (Q, Q / 57.0):
        u = closures.steady_channel_velocity(q, DRHO, MU, c)
        r = closures.flux_channel_radius(q, u, k)
        assert closures.steady_channel_fraction(q, r, u) == pytest.approx(1.0 / k**2, rel=1e-12)
        # closed form R = k (Q mu / (pi c drho g))^(1/4)
        assert r == pytest.approx(k * (q * MU / (math.pi * c * DRHO * STANDARD_GRAVITY)) ** 0.25, rel=1e-12)
    u1, u2 = (closures.steady_channel_velocity(q, DRHO, MU, c) for q in (Q, Q / 57.0))
    r1, r2 = closures.flux_channel_radius(Q, u1, k), closures.flux_channel_radius(Q / 57.0, u2, k)
    assert r1 / r2 == pytest.approx(57.0**0.25, rel=1e-12)
    assert closures.flux_channel_radius(0.0, 0.0, k) == 0.0


def test_diluted_radius_holds_the_feed_at_the_reynolds_diluted_fraction():
    """pi R^2 u phi_p = Q with phi_p = 1 / (k_R^2 (1 + Re / Re_d)), Re = rho_s u R / mu at the returned R, to
    round-off, over a 57-fold feed; the flux form's radius as Re_d grows without bound; and, with a case, the
    radius no wider than the inlet, and the law refused without the flux form."""
    c, k = 0.37, 5.0
    for q, re_d in ((Q, 2.3), (Q / 57.0, 2.3), (Q, 0.05)):
        u = closures.steady_channel_velocity(q, DRHO, MU, c)
        r = closures.diluted_channel_radius(q, u, k, re_d, RHO_S, MU)
        reynolds = closures.plume_reynolds(u, r, RHO_S, MU)
        assert closures.steady_channel_fraction(q, r, u) == pytest.approx(1.0 / (k**2 * (1.0 + reynolds / re_d)),
                                                                         rel=1e-12)
        assert r > closures.flux_channel_radius(q, u, k)
    u = closures.steady_channel_velocity(Q, DRHO, MU, c)
    assert closures.diluted_channel_radius(Q, u, k, 1e12, RHO_S, MU) == pytest.approx(
        closures.flux_channel_radius(Q, u, k), rel=1e-9)
    assert closures.diluted_channel_radius(0.0, u, k, 2.3, RHO_S, MU) == 0.0
    keys = {"case.calibration": "none", "popbal.channel_radius_form": "flux", "popbal.channel_coefficient": 0.37,
            "popbal.channel_radius_factor": 5.0}
    radius = channel_closure(load_case("simple", {**keys, "popbal.plume_dilution_reynolds": 2.3}))[0]
    u = closures.steady_channel_velocity(Q, DRHO, MU, c)
    assert radius == pytest.approx(closures.diluted_channel_radius(Q, u, k, 2.3, RHO_S, MU), rel=1e-3)
    assert channel_closure(load_case("simple", {**keys, "popbal.plume_dilution_reynolds": 1e-4}))[0] == 0.075
    from settler.errors import CaseError
    with pytest.raises(CaseError, match="plume_dilution_reynolds = 2.3.*channel_radius_form = 'inlet'"):
        popbal.setup("simple", {"case.calibration": "none", "popbal.plume_dilution_reynolds": 2.3})


def test_transport_factor():
    """1 / (1 + Re / Re_c): 1/2 at Re = Re_c, 1 without a scale."""
    assert closures.transport_factor(2.0, 2.0) == 0.5
    assert closures.transport_factor(7.0, None) == 1.0


def test_case_closure_by_hand():
    """The simple case with the 'flux' form: u_s, R_c and Re against the numbers computed by hand (c = 0.37, k = 5:
    u_s = sqrt(0.37 x 1.686e-6 x 1950 x 9.80665 / (pi 0.45)) = 91.9 mm/s, R_c = 5 sqrt(Q / (pi u_s)) = 12.1 mm,
    Re = 3150 x 0.0919 x 0.0121 / 0.45 = 7.77); the inlet form keeps R_c = k x 75 mm whatever the feed."""
    case = load_case("simple", {"case.calibration": "none", "popbal.channel_radius_form": "flux",
                                "popbal.channel_coefficient": 0.37, "popbal.channel_radius_factor": 5.0,
                                "popbal.plume_reynolds_scale": 2.0})
    radius, velocity, reynolds, transport = channel_closure(case)
    assert velocity == pytest.approx(0.0919, rel=2e-3)
    assert radius == pytest.approx(0.0121, rel=5e-3)
    assert reynolds == pytest.approx(7.77, rel=1e-2)
    assert transport == pytest.approx(1.0 / (1.0 + reynolds / 2.0), rel=1e-12)
    inlet = load_case("simple", {"case.calibration": "none", "popbal.channel_radius_factor": 0.5,
                                 "feed.mass_rate": 0.001})
    assert channel_closure(inlet)[0] == pytest.approx(0.5 * 0.075, rel=1e-12)


@pytest.mark.parametrize("reynolds_scale, confined", [(None, False), (7.77, False), (None, True),
                                                     (None, "line_force")])
def test_steady_axis_velocity_is_the_plume_velocity(reynolds_scale, confined):
    """Coalescence off, 'flux' form: the channel_velocity output at mid-height over 8-12 s is u_s within 5 %, with
    the droplets carried at u_s (Re_c absent) or at u_s / (1 + Re / Re_c) = u_s / 2 (Re_c = Re = 7.77: then the
    plume holds twice the matte and the output still reports the slag's u_s). Confined (the demo with a channel of
    R / R_c = 2.64, where c(R / R_c) = 0.41): the droplets' cloud law must carry the confined u_s too, not the
    unconfined plume's sqrt(1 / 0.41) = 1.56 times faster one (what it did before the cloud law took c(R / R_c)).
    With popbal.plume_law = 'line_force' the cloud law carries that law's u_s (c = A0 / 4) as well."""
    overrides = {"case.calibration": "none", "coalescence.enabled": False, "popbal.channel_radius_form": "flux",
                 "popbal.channel_coefficient": 0.37, "popbal.channel_radius_factor": 10.0 if confined else 5.0,
                 "popbal.end_time": 12.0, "popbal.output_interval": 0.5, "popbal.height_cells": 25,
                 "popbal.sections_per_doubling": 1, "popbal.confinement": bool(confined)}
    if confined == "line_force":
        overrides["popbal.plume_law"] = "line_force"
    if reynolds_scale is not None:
        overrides["popbal.plume_reynolds_scale"] = reynolds_scale
    case = load_case("demo" if confined else "simple", overrides)
    radius, u_s, _, transport = channel_closure(case)
    if confined is True:
        from popbal.model import column_radius

        assert closures.confined_plume_coefficient(column_radius(case) / radius) == pytest.approx(0.41, abs=0.01)
    series = popbal.run(popbal.setup(case), progress=False).timeseries
    steady = series[(series["time"] >= 8.0) & (series["time"] <= 12.0)]
    assert np.mean(steady["channel_velocity"]) == pytest.approx(u_s, rel=0.05)
    if reynolds_scale is not None:
        assert transport == pytest.approx(0.5, rel=0.01)


def test_a_fixed_channel_radius_gives_the_line_force_plume_its_square_root_law():
    """'fixed' form: R_c is popbal.channel_radius at every feed, so under the confined line-force law u_s^2 =
    c_ch A0(R / R_c) Q drho g / (4 pi mu) by hand, and four times the feed moves the plume exactly twice as fast
    (the full runs' compact plumes: 41.9 to 82.4 mm/s from half to twice the demo's feed)."""
    from popbal.model import column_radius

    overrides = {"case.calibration": "none", "popbal.channel_radius_form": "fixed", "popbal.channel_radius": 0.0105,
                 "popbal.channel_radius_factor": 1.0, "popbal.confinement": True, "popbal.plume_law": "line_force",
                 "popbal.channel_coefficient": 1.0, "popbal.channel_feed_fraction": 1.0}
    case = load_case("demo", overrides)
    radius, velocity, _, _ = channel_closure(case)
    q = case.feed.mass_rate / case.matte.density
    a0 = closures.confined_axis_coefficient(column_radius(case) / 0.0105)
    by_hand = math.sqrt(a0 * q * (case.matte.density - case.slag.density) * STANDARD_GRAVITY
                        / (4 * math.pi * case.slag_viscosity))
    assert radius == 0.0105 and velocity == pytest.approx(by_hand, rel=1e-9)
    quadruple = load_case("demo", {**overrides, "feed.mass_rate": 4 * case.feed.mass_rate})
    assert channel_closure(quadruple)[0] == 0.0105
    assert channel_closure(quadruple)[1] == pytest.approx(2 * velocity, rel=1e-9)
    assert channel_closure(load_case("demo", {**overrides, "popbal.channel_radius_factor": 0.0}))[0] == 0.0


@pytest.mark.parametrize("extra", [{"popbal.channel_radius_form": "fixed"}, {"popbal.channel_radius": 0.01},
                                   {"popbal.channel_radius_form": "flux", "popbal.channel_radius": 0.01}])
def test_the_fixed_radius_and_its_form_go_together(extra):
    from settler.errors import CaseError

    with pytest.raises(CaseError, match="popbal.channel_radius = .*allowed: both together"):
        channel_closure(load_case("demo", {"case.calibration": "none", **extra}))


def test_the_slag_core_radius_sets_the_plume_law_and_bounds_the_droplets_channel():
    """popbal.plume_core_radius R_s: the confined line-force law takes A0(R / R_s) whatever the droplets' channel
    radius R_c (u_s^2 = c_ch A0(R / R_s) Q drho g / (4 pi mu) by hand, the same at R_c = 3 and 6 mm), the return
    flow the slag core's share S(R / R_s), and a flux-form channel wider than R_s is held at R_s. Without R_s the
    law takes R_c, as before (the test above)."""
    from popbal.model import column_radius

    core = 0.012
    overrides = {"case.calibration": "none", "popbal.channel_radius_form": "fixed", "popbal.channel_radius": 0.003,
                 "popbal.channel_radius_factor": 1.0, "popbal.confinement": True, "popbal.plume_law": "line_force",
                 "popbal.channel_coefficient": 1.0, "popbal.channel_feed_fraction": 1.0,
                 "popbal.plume_core_radius": core, "popbal.return_flow_ratio": 1.0}
    case = load_case("demo", overrides)
    radius, velocity, _, _ = channel_closure(case)
    q = case.feed.mass_rate / case.matte.density
    a0 = closures.confined_axis_coefficient(column_radius(case) / core)
    by_hand = math.sqrt(a0 * q * (case.matte.density - case.slag.density) * STANDARD_GRAVITY
                        / (4 * math.pi * case.slag_viscosity))
    assert radius == 0.003 and velocity == pytest.approx(by_hand, rel=1e-9)
    wider = load_case("demo", {**overrides, "popbal.channel_radius": 0.006})
    assert channel_closure(wider)[:2] == (0.006, pytest.approx(velocity, rel=1e-12))
    model = popbal.setup(case)
    share = closures.confined_return_share(column_radius(case) / core)
    assert model.return_velocity == pytest.approx(closures.return_velocity(share, velocity), rel=1e-9)
    flux = load_case("demo", {**overrides, "popbal.channel_radius_form": "flux", "popbal.channel_radius": None,
                              "popbal.channel_radius_factor": 50.0})
    assert channel_closure(flux)[0] == core


@pytest.mark.parametrize("extra, message", [({"popbal.confinement": False}, "allowed only with popbal.confinement"),
                                            ({"popbal.plume_core_radius": 0.06}, "narrower than the column's"),
                                            ({"popbal.spread_flux_reynolds": 0.5}, "allowed: both"),
                                            ({"popbal.plume_core_radius": None, "popbal.spread_core_share": 0.4},
                                             None)])
def test_the_slag_core_radius_is_refused_where_it_means_nothing(extra, message):
    from settler.errors import CaseError

    overrides = {"case.calibration": "none", "popbal.confinement": True, "popbal.plume_core_radius": 0.012, **extra}
    match = f"popbal.plume_core_radius = .*{message}" if message and "both" not in message else \
        ("popbal.spread_flux_reynolds = 0.5 with popbal.spread_core_share = None: allowed: both" if message else
         "popbal.spread_core_share = 0.4: bounds or replaces the slag core popbal.plume_core_radius; allowed only")
    with pytest.raises(CaseError, match=match):
        channel_closure(load_case("demo", {k: v for k, v in overrides.items() if v is not None}))


def test_the_slag_core_spreads_over_the_column_at_the_feed_reynolds_number_and_is_bounded_in_narrow_columns():
    """R_s is plume_core_radius R_0 while rho_s Q / (mu R_0) stays below spread_flux_reynolds, and
    spread_core_share x the column radius R at and above it (the demo at 0.31 against 1.24 at four times its feed,
    with R_0 = 9.5 mm); plume_core_column_share beta caps it at beta R (deep's feed in its 20 mm column)."""
    from popbal.model import column_radius, core_radius

    base = {"case.calibration": "none", "popbal.confinement": True, "popbal.plume_core_radius": 0.0095,
            "popbal.spread_flux_reynolds": 0.66, "popbal.spread_core_share": 0.4, "popbal.channel_feed_fraction": 1.0}
    demo = load_case("demo", base)
    q = demo.feed.mass_rate / demo.matte.density
    assert closures.feed_reynolds(q, 0.0095, demo.slag.density, demo.slag_viscosity) == pytest.approx(
        3150.0 * q / (0.45 * 0.0095), rel=1e-12) and 3150.0 * q / (0.45 * 0.0095) < 0.66
    assert core_radius(demo) == 0.0095
    fast = load_case("demo", {**base, "feed.mass_rate": 4 * demo.feed.mass_rate})
    assert core_radius(fast) == pytest.approx(0.4 * column_radius(fast), rel=1e-12)
    assert channel_closure(fast)[0] <= core_radius(fast)
    narrow = load_case("deep", {**base, "geometry.width": 0.02, "geometry.depth": 0.02,
                                "popbal.plume_core_column_share": 0.62})
    assert core_radius(narrow) == pytest.approx(0.62 * math.sqrt(0.02 * 0.02 / math.pi), rel=1e-12)
    wide = load_case("deep", {**base, "popbal.plume_core_column_share": 0.62})
    assert core_radius(wide) == 0.0095


def test_the_compact_core_grows_as_a_power_of_the_feed_reynolds_number_and_fills_a_column_its_inlet_spans():
    """With plume_core_exponent n the compact core is R_0 (Re_Q / Re_Q,0)^n, Re_Q = rho_s Q / (mu L) at L =
    spread_reference_radius: R_0 at Re_Q,0 by construction (the demo's own Re_Q given), 2^n R_0 at twice the feed and
    2^-n R_0 at twice the viscosity (Re_Q is linear in Q / mu), the same in deep's 50 and 20 mm columns without the
    fill rule; with plume_fill_inlet_share 0.78 deep's inlet (10 mm in the 20 mm column, 0.89 R) fills its column
    (core beta R) while the demo's (37.5 mm in 56.4 mm, 0.66 R) and deep's 50 mm column's (0.35 R) neck; the confined
    law takes the grown core (u_s by hand)."""
    from popbal.model import column_radius, core_radius

    n, length = 0.3, 0.0095
    demo = load_case("demo", {"case.calibration": "none"})
    re_0 = closures.feed_reynolds(demo.feed.mass_rate / demo.matte.density, length, demo.slag.density,
                                  demo.slag_viscosity)
    base = {"case.calibration": "none", "popbal.confinement": True, "popbal.plume_core_radius": 0.0095,
            "popbal.spread_flux_reynolds": 10.0, "popbal.spread_core_share": 0.4, "popbal.channel_feed_fraction": 1.0,
            "popbal.spread_reference_radius": length, "popbal.plume_core_exponent": n,
            "popbal.plume_core_reynolds": re_0, "popbal.plume_core_column_share": 0.62}
    assert core_radius(load_case("demo", base)) == pytest.approx(0.0095, rel=1e-12)
    double = load_case("demo", {**base, "feed.mass_rate": 2 * demo.feed.mass_rate})
    assert core_radius(double) == pytest.approx(0.0095 * 2**n, rel=1e-12)
    viscous = load_case("demo", {**base, "slag.viscosity_reference": 2 * demo.slag.viscosity_reference})
    assert viscous.slag_viscosity == pytest.approx(2 * demo.slag_viscosity, rel=1e-12)
    assert core_radius(viscous) == pytest.approx(0.0095 * 2**-n, rel=1e-12)
    deep = load_case("deep", {"case.calibration": "none"})
    deep_re = closures.feed_reynolds(deep.feed.mass_rate / deep.matte.density, length, deep.slag.density,
                                     deep.slag_viscosity)
    narrow = {"geometry.width": 0.02, "geometry.depth": 0.02}
    law = 0.0095 * (deep_re / re_0) ** n
    assert law < 0.62 * math.sqrt(0.02 * 0.02 / math.pi)  # the column's bound does not reach it
    for extra in ({}, narrow):
        assert core_radius(load_case("deep", {**base, **extra})) == pytest.approx(law, rel=1e-12)
    fill = {**base, "popbal.plume_fill_inlet_share": 0.78}
    assert core_radius(load_case("deep", {**fill, **narrow})) == pytest.approx(
        0.62 * math.sqrt(0.02 * 0.02 / math.pi), rel=1e-12)
    assert core_radius(load_case("deep", fill)) == pytest.approx(law, rel=1e-12)
    assert core_radius(load_case("demo", fill)) == pytest.approx(0.0095, rel=1e-12)
    line = load_case("demo", {**fill, "popbal.plume_law": "line_force", "popbal.channel_coefficient": 1.0,
                              "feed.mass_rate": 2 * demo.feed.mass_rate})
    q = line.feed.mass_rate / line.matte.density
    a0 = closures.confined_axis_coefficient(column_radius(line) / (0.0095 * 2**n))
    assert channel_closure(line)[1] == pytest.approx(math.sqrt(
        a0 * q * (line.matte.density - line.slag.density) * STANDARD_GRAVITY / (4 * math.pi * line.slag_viscosity)),
        rel=1e-9)


def test_a_spread_plume_ignores_the_compact_law_but_its_keys_are_still_checked():
    """A plume the regime rule spreads (the demo at four times its feed: Re_Q 1.24 against the boundary 0.66) takes
    spread_core_share x R whatever the compact law and the fill rule say; the law's keys are refused as for a compact
    plume (not silently accepted because the law is not used)."""
    from popbal.model import column_radius, core_radius
    from settler.errors import CaseError

    demo = load_case("demo", {"case.calibration": "none"})
    overrides = {"case.calibration": "none", "popbal.confinement": True, "popbal.plume_core_radius": 0.0095,
                 "popbal.spread_flux_reynolds": 0.66, "popbal.spread_core_share": 0.4,
                 "popbal.spread_reference_radius": 0.0095, "popbal.plume_core_exponent": 0.3,
                 "popbal.plume_core_reynolds": 0.025, "popbal.plume_core_column_share": 0.9,
                 "popbal.plume_fill_inlet_share": 0.5, "feed.mass_rate": 4 * demo.feed.mass_rate}
    fast = load_case("demo", overrides)
    assert core_radius(fast) == pytest.approx(0.4 * column_radius(fast), rel=1e-12)
    with pytest.raises(CaseError, match="plume_core_exponent = 0.3 with popbal.plume_core_reynolds = None"):
        core_radius(load_case("demo", {k: v for k, v in overrides.items() if k != "popbal.plume_core_reynolds"}))


@pytest.mark.parametrize("extra, match", [
    ({"popbal.plume_core_reynolds": None},
     "plume_core_exponent = 0.3 with popbal.plume_core_reynolds = None: allowed: both"),
    ({"popbal.spread_reference_radius": None, "popbal.spread_flux_reynolds": None, "popbal.spread_core_share": None},
     "plume_core_exponent = 0.3: the growth .* allowed only with both"),
    ({"popbal.plume_fill_inlet_share": 0.78}, "plume_fill_inlet_share = 0.78: .* allowed only with plume_core_column"),
    ({"popbal.plume_core_radius": None, "popbal.spread_reference_radius": None, "popbal.spread_flux_reynolds": None,
      "popbal.spread_core_share": None}, "plume_core_exponent = 0.3: bounds or replaces the slag core")])
def test_the_core_law_is_refused_without_the_keys_it_needs(extra, match):
    """Each key of the compact core's law refused by name where what it needs is missing, never ignored."""
    from settler.errors import CaseError

    overrides = {"case.calibration": "none", "popbal.confinement": True, "popbal.plume_core_radius": 0.0095,
                 "popbal.spread_flux_reynolds": 0.66, "popbal.spread_core_share": 0.4,
                 "popbal.spread_reference_radius": 0.0095, "popbal.plume_core_exponent": 0.3,
                 "popbal.plume_core_reynolds": 0.31, **extra}
    with pytest.raises(CaseError, match=match):
        channel_closure(load_case("demo", {k: v for k, v in overrides.items() if v is not None}))
