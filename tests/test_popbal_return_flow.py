"""The return flow of popbal's outer zone (popbal.closures, return_flow_ratio): the two-way transport kernel against
the one-way kernel and a dense linear solve, its conservation, and a whole run that keeps the matte balance."""

import numpy as np
import pytest

import popbal
from popbal.closures import return_velocity, settling_share
from popbal.kernels import QUANTITIES, transport_two_way, transport_zone


def _work(cells):
    return np.zeros(cells), np.zeros(cells), np.zeros(cells)


def test_two_way_transport_equals_the_one_way_kernel_when_every_velocity_points_down():
    rng = np.random.default_rng(5)
    cells, sections, dz, dt = 10, 3, 0.01, 0.4
    content = rng.uniform(0.0, 1.0, (cells, QUANTITIES, sections))
    velocity = rng.uniform(0.0, 0.05, (cells, sections))
    sink = np.where(np.arange(cells) == 2, 0.3, 0.0)
    source = rng.uniform(0.0, 1.0, (QUANTITIES, sections))
    one, two = content.copy(), content.copy()
    out_one = np.zeros((2, QUANTITIES, sections))
    out_two = np.zeros((3, QUANTITIES, sections))
    transport_zone(one, velocity, sink, source, dz, dt, out_one[0], out_one[1])
    transport_two_way(two, velocity, sink, source, np.zeros((QUANTITIES, sections)), dz, dt, out_two[0], out_two[1],
                      out_two[2], *_work(cells))
    assert np.allclose(two, one, rtol=1e-12, atol=0.0)
    assert np.allclose(out_two[0], out_one[0], rtol=1e-12) and np.allclose(out_two[2], out_one[1], rtol=1e-12)
    assert not out_two[1].any()


def test_two_way_transport_solves_its_implicit_system_and_conserves_with_mixed_signs():
    """Velocities of both signs: the result satisfies the backward-Euler donor-cell system (built densely here and
    solved by numpy), stays positive, and every droplet is accounted for (in the cells, out at the bottom, out at
    the top, withdrawn)."""
    rng = np.random.default_rng(6)
    cells, sections, dz, dt = 9, 2, 0.01, 0.5
    content = rng.uniform(0.0, 1.0, (cells, QUANTITIES, sections))
    velocity = rng.uniform(-0.03, 0.03, (cells, sections))
    velocity[0] = 0.02  # something leaves at the bottom
    velocity[-1] = -0.02  # and at the top
    sink = np.where(np.arange(cells) == 4, 0.1, 0.0)
    top, bottom_source = rng.uniform(0.0, 1.0, (2, QUANTITIES, sections))
    new = content.copy()
    bottom_out, top_out, sink_out = np.zeros((3, QUANTITIES, sections))
    transport_two_way(new, velocity, sink, top, bottom_source, dz, dt, bottom_out, top_out, sink_out, *_work(cells))
    c = dt / dz
    for k in range(sections):
        v = velocity[:, k]
        a = np.diag(1.0 + c * np.abs(v) + dt * sink)
        for j in range(cells):
            if j + 1 < cells:
                a[j, j + 1] = -c * max(v[j + 1], 0.0)
            if j > 0:
                a[j, j - 1] = -c * max(-v[j - 1], 0.0)
        for q in range(QUANTITIES):
            rhs = content[:, q, k].copy()
            rhs[-1] += dt * top[q, k]
            rhs[0] += dt * bottom_source[q, k]
            assert np.allclose(new[:, q, k], np.linalg.solve(a, rhs), rtol=1e-12)
    before = content.sum(axis=0) * dz + dt * (top + bottom_source) * dz
    after = new.sum(axis=0) * dz + bottom_out + top_out + sink_out
    assert np.allclose(before, after, rtol=1e-13)
    assert np.all(new >= 0.0) and top_out.min() > 0.0 and bottom_out.min() > 0.0


def test_return_flow_closure_values():
    # u_up = r u_s: r = 0.06, u_s = 60 mm/s -> 3.6 mm/s
    assert return_velocity(0.06, 0.06) == pytest.approx(3.6e-3, rel=1e-12)
    assert return_velocity(0.0, 0.06) == 0.0
    assert np.array_equal(settling_share(np.array([0.0, 1e-3, 3e-3]), 2e-3), [0.0, 0.5, 1.0])
    assert np.array_equal(settling_share(np.array([1e-4]), 0.0), [1.0])


def test_a_run_with_the_return_flow_keeps_the_matte_balance_and_holds_more_droplets():
    """The coalescence-off demo for 8 s: with a return flow the matte is conserved to round-off (fed = in slag +
    settled + lost + reacted) and fewer droplets settle, so more stay in the slag, than without (a run without the
    key and with it at 0 are identical)."""
    base = {"coalescence.enabled": False, "popbal.end_time": 8.0, "popbal.channel_radius_form": "flux",
            "popbal.channel_radius_factor": 4.0, "case.calibration": "none"}
    plain = popbal.run(popbal.setup("demo", base), progress=False).timeseries
    zero = popbal.run(popbal.setup("demo", {**base, "popbal.return_flow_ratio": 0.0}), progress=False).timeseries
    back = popbal.run(popbal.setup("demo", {**base, "popbal.return_flow_ratio": 0.05}), progress=False).timeseries
    assert plain.equals(zero)
    assert back["mass_balance_error"].abs().max() < 1e-12
    assert back["mass_settled"].iloc[-1] < plain["mass_settled"].iloc[-1]
    assert back["droplet_count"].iloc[-1] > plain["droplet_count"].iloc[-1]


def test_a_return_flow_without_a_channel_zone_is_refused_in_one_line():
    from settler.cases import CaseError

    with pytest.raises(CaseError, match="popbal.return_flow_ratio = 2.0: needs a channel zone"):
        popbal.setup("demo", {"popbal.return_flow_ratio": 2.0, "popbal.channel_radius_factor": 0.0,
                              "popbal.channel_feed_fraction": 0.0, "case.calibration": "none"})
