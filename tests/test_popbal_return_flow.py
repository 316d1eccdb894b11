"""The return flow of popbal's outer zone (popbal.closures, return_flow_ratio): the two-way transport kernel against
the one-way kernel and a dense linear solve, its conservation, and a whole run that keeps the matte balance."""

import numpy as np
import pytest

import popbal
from popbal import closures
from popbal.closures import return_velocity, settling_share
from popbal.kernels import QUANTITIES, transport_two_way, transport_zone


def _work(cells, sections, loss=None, lateral=None, diffusivity=0.0):
    """The kernel's work space, its sideways loss rate (none by default), the array that books it and the eddy
    diffusivity [m^2/s] (none by default)."""
    return (np.zeros(cells), np.zeros(cells), np.zeros(cells), np.zeros(cells) if loss is None else loss,
            np.zeros((cells, QUANTITIES, sections)) if lateral is None else lateral, diffusivity)


def test_an_eddy_diffused_settling_column_fed_at_the_bottom_takes_mason_weavers_profile():
    """Droplets settling at U through a column stirred by D, fed into the bottom cell and leaving only through the
    floor, reach the steady profile of zero net flux above the bottom, U n + D dn/dz = 0: n ∝ exp(-U z / D) (Mason &
    Weaver 1924). The scheme's own steady state has n_{j+1} / n_j = 1 / (1 + U dz / D) (upwind settling, centred
    diffusion), held to 1e-9 after enough implicit steps; at U dz / D = 0.05 that is exp(-U dz / D) within 0.13 %
    (the first-order error (U dz / D)^2 / 2). Without diffusion nothing rises above the bottom cell."""
    cells, sections, dz, dt = 40, 2, 0.005, 2.0
    u = np.array([0.6e-3, 4.7e-3])
    diffusivity = u * dz / 0.05  # U dz / D = 0.05 for each section: D = 6e-5 and 4.7e-4 m^2/s
    for k in range(sections):
        content = np.zeros((cells, QUANTITIES, sections))
        velocity = np.zeros((cells, sections))
        velocity[:, k] = u[k]
        source = np.zeros((QUANTITIES, sections))
        source[:, k] = 1.0
        outs = np.zeros((3, QUANTITIES, sections))
        for _ in range(4000):
            transport_two_way(content, velocity, np.zeros(cells), np.zeros((QUANTITIES, sections)), source, dz, dt,
                              outs[0], outs[1], outs[2], *_work(cells, sections, diffusivity=diffusivity[k]))
        ratio = content[1:, 0, k] / content[:-1, 0, k]
        assert ratio == pytest.approx(np.full(cells - 1, 1.0 / 1.05), rel=1e-9)
        assert ratio == pytest.approx(np.full(cells - 1, np.exp(-0.05)), rel=1.3e-3)
        # steady: what is fed leaves through the floor, at U n_0
        assert u[k] * content[0, 0, k] == pytest.approx(1.0 * dz, rel=1e-9)
    still = np.zeros((cells, QUANTITIES, sections))
    velocity = np.tile(u, (cells, 1))
    transport_two_way(still, velocity, np.zeros(cells), np.zeros((QUANTITIES, sections)),
                      np.ones((QUANTITIES, sections)), dz, dt, *np.zeros((3, QUANTITIES, sections)),
                      *_work(cells, sections))
    assert not still[1:].any()


def test_eddy_diffusion_alone_conserves_what_a_column_holds_and_evens_it_out():
    """No velocity, no source or sink: the content of a closed column is kept to round-off over 500 steps and tends
    to uniform (no flux through the top or the bottom)."""
    rng = np.random.default_rng(2)
    cells, sections, dz, dt = 20, 3, 0.005, 1.0
    content = rng.uniform(0.0, 1.0, (cells, QUANTITIES, sections))
    total = content.sum(axis=0)
    outs = np.zeros((3, QUANTITIES, sections))
    for _ in range(500):
        transport_two_way(content, np.zeros((cells, sections)), np.zeros(cells), np.zeros((QUANTITIES, sections)),
                          np.zeros((QUANTITIES, sections)), dz, dt, outs[0], outs[1], outs[2],
                          *_work(cells, sections, diffusivity=5e-4))
    assert content.sum(axis=0) == pytest.approx(total, rel=1e-12)
    assert not outs.any()
    assert np.ptp(content, axis=0).max() < 1e-6 * total.max()


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
                      out_two[2], *_work(cells, sections))
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
    loss = rng.uniform(0.0, 0.2, cells)  # the plume's entrainment: a sideways loss, booked per cell
    lateral = np.zeros((cells, QUANTITIES, sections))
    transport_two_way(new, velocity, sink, top, bottom_source, dz, dt, bottom_out, top_out, sink_out,
                      *_work(cells, sections, loss, lateral))
    c = dt / dz
    for k in range(sections):
        v = velocity[:, k]
        a = np.diag(1.0 + c * np.abs(v) + dt * sink + dt * loss)
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
    after = new.sum(axis=0) * dz + bottom_out + top_out + sink_out + lateral.sum(axis=0) * dz
    assert np.allclose(before, after, rtol=1e-13)
    assert np.allclose(lateral, dt * loss[:, None, None] * new, rtol=1e-13)
    assert np.all(new >= 0.0) and top_out.min() > 0.0 and bottom_out.min() > 0.0


def test_entrainment_keeps_the_slags_continuity_so_uniform_content_stays_uniform():
    """Droplets that follow the slag (no settling) in an upflow that falls with height, the plume entraining e_j =
    (u_{j-1} - u_j) / dz of each cell per second (popbal.closures.exchange_rates) and the slag coming in through the
    bottom as full as the cells: the content stays uniform whatever the step, the cells lose dt e_j c sideways and
    the top passes dt u_top c."""
    cells, sections, dz, dt = 12, 2, 0.005, 0.7
    upflow = 4e-3 * closures.circulation_profile((np.arange(cells) + 0.5) * dz, cells * dz, 0.034, 1.0, 0.05)
    rates = closures.exchange_rates(upflow, dz)
    assert rates[0] < 0.0 and np.all(rates[np.argmax(upflow) + 1:] > 0.0)
    content = np.full((cells, QUANTITIES, sections), 2.5)
    velocity = np.repeat(-upflow[:, None], sections, axis=1)
    bottom_source = np.full((QUANTITIES, sections), upflow[0] * 2.5 / dz)  # through the floor face, u_0 c / dz
    lateral = np.zeros((cells, QUANTITIES, sections))
    bottom_out, top_out, sink_out = np.zeros((3, QUANTITIES, sections))
    rising = upflow >= np.concatenate([[0.0], upflow[:-1]])
    assert rising[: np.argmax(upflow) + 1].all()  # the cells up to the peak gain slag: give it them as full
    gains = np.where(rising, -rates, 0.0)
    gains[0] = 0.0  # cell 0's comes through the floor face (bottom_source)
    content_before = content.copy()
    content += dt * gains[:, None, None] * 2.5  # the slag given back below the peak, as full, explicitly
    transport_two_way(content, velocity, np.zeros(cells), np.zeros((QUANTITIES, sections)), bottom_source, dz, dt,
                      bottom_out, top_out, sink_out, *_work(cells, sections, np.maximum(rates, 0.0), lateral))
    # the gain, added before the implicit transport at the uniform value that is the solution, keeps it exactly too
    assert content == pytest.approx(content_before, rel=1e-12)
    expected = np.broadcast_to(dt * np.maximum(rates, 0.0)[:, None, None] * 2.5, lateral.shape)
    assert lateral == pytest.approx(expected, rel=1e-12, abs=1e-300)
    assert top_out == pytest.approx(dt * upflow[-1] * 2.5, rel=1e-12)


def test_circulation_profile_peaks_at_one_and_vanishes_at_the_lid_and_floor():
    height, radius = 0.1, 0.0564
    z = np.linspace(0.0, height, 11)
    s = closures.circulation_profile(z, height, radius, 1.12, 0.54)
    fine = np.linspace(0.0, height, 200_001)
    peak = (-np.expm1(-(height - fine) / (1.12 * radius)) * -np.expm1(-fine / (0.54 * radius))).max()
    expected = -np.expm1(-(height - z) / (1.12 * radius)) * -np.expm1(-z / (0.54 * radius)) / peak
    assert s == pytest.approx(expected, rel=1e-5)  # its own peak is the largest of 2001 samples
    assert s[0] == 0.0 and s[-1] == 0.0
    assert closures.circulation_profile(fine, height, radius, 1.12, 0.54).max() == pytest.approx(1.0, rel=1e-5)
    assert 0.3 < z[np.argmax(s)] / height < 0.5  # the continued demo_cell_25's Q_down peaks at 0.39 H
    rates = closures.exchange_rates(np.array([1.0, 3.0, 2.0, 0.5]), 0.01)
    assert rates == pytest.approx([-100.0, -200.0, 100.0, 150.0])


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


def test_an_eddy_diffusivity_without_a_return_flow_is_refused_and_zero_changes_nothing():
    """popbal.outer_dispersion stirs the return flow's zone: without a return flow it is refused by name; at 0 the
    run is the one without the key, to the last digit."""
    from settler.cases import CaseError

    with pytest.raises(CaseError, match=r"popbal.outer_dispersion = 0.0005 m\^2/s: stirs a return flow"):
        popbal.setup("demo", {"popbal.outer_dispersion": 5e-4, "popbal.return_flow_ratio": 0.0,
                              "case.calibration": "none"})
    keys = {"popbal.return_flow_ratio": 1.0, "popbal.end_time": 3.0, "case.calibration": "none"}
    plain = popbal.run(popbal.setup("demo", keys), progress=False).timeseries
    zero = popbal.run(popbal.setup("demo", {**keys, "popbal.outer_dispersion": 0.0}), progress=False).timeseries
    stirred = popbal.run(popbal.setup("demo", {**keys, "popbal.outer_dispersion": 5e-4}), progress=False).timeseries
    assert zero.equals(plain)
    assert not stirred["droplet_count"].equals(plain["droplet_count"])


def test_with_eddy_diffusion_every_droplet_is_booked_whatever_the_velocities():
    """Velocities of either sign, a sink, the plume's sideways loss, sources at the top and the bottom and D > 0: what
    the column holds after 50 steps plus what left through the floor, the top, the sink and the side equals what it
    held plus what was fed, per section and quantity, to round-off."""
    rng = np.random.default_rng(9)
    cells, sections, dz, dt = 15, 4, 0.01, 0.3
    content = rng.uniform(0.0, 1.0, (cells, QUANTITIES, sections))
    velocity = rng.uniform(-3e-3, 3e-3, (cells, sections))
    sink = rng.uniform(0.0, 0.05, cells)
    loss = rng.uniform(0.0, 0.1, cells)
    top, bottom = rng.uniform(0.0, 1.0, (2, QUANTITIES, sections))
    before = content.sum(axis=0) * dz
    outs = np.zeros((3, QUANTITIES, sections))
    lateral = np.zeros((cells, QUANTITIES, sections))
    steps = 50
    for _ in range(steps):
        transport_two_way(content, velocity, sink, top, bottom, dz, dt, outs[0], outs[1], outs[2],
                          *_work(cells, sections, loss, lateral, diffusivity=4e-4))
    after = content.sum(axis=0) * dz + outs.sum(axis=0) + lateral.sum(axis=0) * dz
    assert after == pytest.approx(before + steps * dt * (top + bottom) * dz, rel=1e-12)
