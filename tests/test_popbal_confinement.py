"""popbal's confinement closure (popbal.closures, ``popbal.confinement``): the confined Stokes plume's coefficient
and return flow against a direct numerical solution of the same flow, and the model's use of them."""

import math

import numpy as np
import pytest

import popbal
from popbal import closures
from settler.cases import CaseError, load_case
from settler.physics import STANDARD_GRAVITY


def stokes_column(column_to_core, points=400_001):
    """The confined Stokes plume solved numerically (R = 1, force 1 per unit height, mu = 1): the velocity from
    integrating mu (1/r)(r w')' = G - F(r) twice with the trapezoid rule (no slip at r = 1), G from zero net flux
    by superposition. Returns r, w."""
    a = 1.0 / column_to_core
    r = np.linspace(0.0, 1.0, points)
    force = np.where(r <= a, 1.0 / (math.pi * a * a), 0.0)

    def solve(source):
        # r w' = int_0^r source r' dr' ; w(1) = 0
        inner = np.concatenate([[0.0], np.cumsum(0.5 * (source[1:] * r[1:] + source[:-1] * r[:-1]) * np.diff(r))])
        slope = np.divide(inner, r, out=np.zeros_like(r), where=r > 0)
        w = np.concatenate([[0.0], np.cumsum(0.5 * (slope[1:] + slope[:-1]) * np.diff(r))])
        return w - w[-1]

    by_force, by_gradient = solve(-force), solve(np.ones_like(r))
    flux = lambda w: np.trapezoid(w * 2.0 * math.pi * r, r)  # noqa: E731
    w = by_force - flux(by_force) / flux(by_gradient) * by_gradient
    return r, w


@pytest.mark.parametrize("column_to_core", [1.1, 1.5, 1.72, 1.85, 2.0, 3.3, 6.2, 10.8, 20.0])
def test_return_flow_and_coefficient_match_the_numerical_stokes_column(column_to_core):
    """Axis coefficient A0, return radius r_0 and the mean upflow over the axis velocity S from the closed forms,
    against the numerically integrated flow (net flux zero to 1e-6 of the downflow; 4e5 points: within 1e-4),
    below R/a = 1.78 too, where the slag turns inside the core."""
    r, w = stokes_column(column_to_core)
    axis = w[0]
    assert 4.0 * math.pi * axis == pytest.approx(closures.confined_axis_coefficient(column_to_core), rel=1e-4)
    up = w < 0.0
    turn = r[np.argmax(up)]
    assert turn == pytest.approx(closures.confined_return_radius(column_to_core), abs=1e-4)
    upflux = -np.trapezoid(np.where(up, w, 0.0) * 2.0 * math.pi * r, r)
    downflux = np.trapezoid(np.where(up, 0.0, w) * 2.0 * math.pi * r, r)
    assert upflux == pytest.approx(downflux, rel=1e-6)
    share = upflux / (math.pi * (1.0 - turn**2)) / axis
    assert share == pytest.approx(closures.confined_return_share(column_to_core), rel=1e-3)
    a = 1.0 / column_to_core
    core = np.trapezoid(np.where(r <= a, w, 0.0) * 2.0 * math.pi * r, r) / (math.pi * a * a)
    coefficient = (4.0 * math.pi * axis) ** 2 / (4.0 * 4.0 * math.pi * core)
    assert coefficient == pytest.approx(closures.confined_plume_coefficient(column_to_core), rel=1e-3)


def test_confinement_values_of_the_reference_notes():
    """reduced-model.md section 2: c = 1.39, 1.05, 0.71, 0.51, 0.29 at R/a = 20, 10, 5, 3.3, 2; the slag turns up at
    about 0.46 R; NaN where there is no column around the core."""
    for ratio, c in ((20, 1.39), (10, 1.05), (5, 0.71), (3.3, 0.51), (2, 0.29)):
        assert closures.confined_plume_coefficient(ratio) == pytest.approx(c, abs=0.005)
    assert 0.44 < closures.confined_return_radius(10.0) < 0.48
    for f in (closures.confined_plume_coefficient, closures.confined_return_share, closures.confined_return_radius):
        assert math.isnan(f(1.0))


def test_the_model_solves_radius_and_velocity_together():
    """With confinement and the flux radius form, the model's u_s and R_c satisfy both u_s^2 = c_ch c(R/R_c) Q drho
    g / (pi mu) and R_c = k_R sqrt(Q / (pi u_s)) to 1e-10, and its return upflow is r S(R/R_c) u_s."""
    overrides = {"case.calibration": "none", "popbal.channel_radius_form": "flux", "popbal.channel_radius_factor": 4.0,
                 "popbal.confinement": True, "popbal.channel_coefficient": 0.7, "popbal.return_flow_ratio": 0.8,
                 "popbal.height_cells": 10}
    case = load_case("demo", overrides)
    model = popbal.setup(case)
    u, radius = model.parameters["plume_velocity"], model.channel_radius
    q = case.feed.mass_rate * case.popbal.channel_feed_fraction / case.matte.density
    column = math.sqrt(case.geometry.width * case.geometry.depth / math.pi)
    drho = case.matte.density - case.slag.density
    c = closures.confined_plume_coefficient(column / radius)
    assert u**2 == pytest.approx(0.7 * c * q * drho * STANDARD_GRAVITY / (math.pi * case.slag_viscosity), rel=1e-10)
    assert radius == pytest.approx(4.0 * math.sqrt(q / (math.pi * u)), rel=1e-10)
    assert model.return_velocity == pytest.approx(0.8 * closures.confined_return_share(column / radius) * u, rel=1e-12)
    plain = popbal.setup(load_case("demo", {**overrides, "popbal.confinement": False}))
    assert plain.return_velocity == pytest.approx(0.8 * plain.parameters["plume_velocity"], rel=1e-12)


def test_a_channel_as_wide_as_the_column_is_refused():
    with pytest.raises(CaseError, match=r"popbal.confinement = true: the channel .* reaches the column"):
        popbal.setup(load_case("demo", {"case.calibration": "none", "popbal.channel_radius_form": "flux",
                                        "popbal.channel_radius_factor": 60.0, "popbal.confinement": True}))


def test_the_line_force_law_solves_radius_and_velocity_together_and_needs_confinement():
    """popbal.plume_law = 'line_force': u_s^2 = c_ch (A0(R/R_c) / 4) Q drho g / (pi mu), A0 = 2 ln(R/R_c) - 1 +
    (R_c/R)^2 the confined line force's axis coefficient, with R_c = k_R sqrt(Q / (pi u_s)), to 1e-10, and the return
    flow r S(R/R_c) u_s of the uniform core's share; without confinement the key is refused by name."""
    overrides = {"case.calibration": "none", "popbal.channel_radius_form": "flux", "popbal.channel_radius_factor": 4.0,
                 "popbal.confinement": True, "popbal.channel_coefficient": 0.7, "popbal.height_cells": 10}
    case = load_case("demo", {**overrides, "popbal.plume_law": "line_force", "popbal.return_flow_ratio": 0.8})
    model = popbal.setup(case)
    u, radius = model.parameters["plume_velocity"], model.channel_radius
    q = case.feed.mass_rate * case.popbal.channel_feed_fraction / case.matte.density
    column = math.sqrt(case.geometry.width * case.geometry.depth / math.pi)
    drho = case.matte.density - case.slag.density
    a0 = 2.0 * math.log(column / radius) - 1.0 + (radius / column) ** 2
    assert u**2 == pytest.approx(0.7 * a0 / 4.0 * q * drho * STANDARD_GRAVITY / (math.pi * case.slag_viscosity),
                                 rel=1e-10)
    assert radius == pytest.approx(4.0 * math.sqrt(q / (math.pi * u)), rel=1e-10)
    # the return flow keeps the uniform core's share S(R/R_c) of the (line-force) axis velocity
    assert model.return_velocity == pytest.approx(0.8 * closures.confined_return_share(column / radius) * u, rel=1e-12)
    with pytest.raises(CaseError, match=r"popbal.plume_law = 'line_force': .* only with popbal.confinement = true"):
        popbal.setup(load_case("demo", {**overrides, "popbal.confinement": False, "popbal.plume_law": "line_force"}))
