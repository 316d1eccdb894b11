"""analysis.plume_force: the confined Stokes axis velocity a band's droplets drive, against the closed form of a
uniform core, an independent finite-difference solution of the same flow (for rings and for the engine's Gaussian
spreading of a droplet's force), and on a constructed run."""

import math

import numpy as np
import pytest

from analysis.plume_force import (GRAVITY, measure_plume_force, read_plume_force, ring_kernel, smoothed_ring_kernel,
                                  stokes_axis_velocity, write_plume_force)
from popbal.closures import confined_axis_coefficient
from popbal.model import column_radius
from settler.cases import load_case
from settler.output import CHANNEL_PROFILE, band_edges, write_table
from tests.test_floor_lift import _run_folder

MU, DRHO, R = 0.45, 1600.0, 0.0564  # slag viscosity [Pa s], density difference [kg/m^3], column radius [m]


def _finite_difference_axis_velocity(force_density, radius, cells=4000):
    """Axis velocity [m/s] of mu (1/r) d/dr (r dw/dr) = G - f(r) on 0 < r < R (w downward), w(R) = 0, dw/dr(0) = 0 and
    zero net flux fixing G: second-order finite volumes (a tridiagonal system), G from the superposition of the
    force's and a unit G's solutions, the axis value extrapolated as w = a + b r^2. Independent of the kernel's
    algebra."""
    from scipy.linalg import solve_banded

    edges = np.linspace(0.0, radius, cells + 1)
    centres = 0.5 * (edges[1:] + edges[:-1])
    h = edges[1] - edges[0]
    scale = MU / (h * h * centres)
    upper = np.where(np.arange(cells) + 1 < cells, edges[1:], 0.0) * scale  # r_{i+1/2} (w_{i+1} - w_i)
    lower = edges[:-1] * scale  # r_{i-1/2} (w_{i-1} - w_i); zero at the axis
    diagonal = -(edges[:-1] + edges[1:]) * scale
    diagonal[-1] = -(edges[-2] + 2.0 * edges[-1]) * scale[-1]  # w(R) = 0 half a cell beyond the last centre
    bands = np.zeros((3, cells))
    bands[0, 1:] = upper[:-1]
    bands[1] = diagonal
    bands[2, :-1] = lower[1:]
    area = 2.0 * math.pi * centres * h
    w_force = solve_banded((1, 1), bands, -force_density(centres))
    w_unit = solve_banded((1, 1), bands, np.ones(cells))
    w = w_force - np.sum(w_force * area) / np.sum(w_unit * area) * w_unit
    return float(w[0] + (w[0] - w[1]) * centres[0] ** 2 / (centres[1] ** 2 - centres[0] ** 2))


def test_the_ring_kernel_averaged_over_a_uniform_core_is_the_confined_plume_law():
    """K averaged over a disk of radius a (area-weighted midpoint quadrature) is A0 = 2 ln(R/a) - 1 + (a/R)^2, as
    popbal.closures has it, at R/a 1.5, 3 and 12, to 1e-6; beyond R a ring counts as at R (K = 0); K changes sign at
    r/R = 0.451; a ring on the axis and a column without radius are refused, naming the value."""
    for ratio in (1.5, 3.0, 12.0):
        a = R / ratio
        edges = np.linspace(0.0, a, 200001)
        r = 0.5 * (edges[1:] + edges[:-1])
        mean = np.sum(ring_kernel(r, R) * r) / np.sum(r)
        assert mean == pytest.approx(2.0 * math.log(ratio) - 1.0 + ratio**-2, abs=1e-6)
        assert mean == pytest.approx(confined_axis_coefficient(ratio), abs=1e-6)
    assert ring_kernel(2.0 * R, R) == 0.0 and ring_kernel(R, R) == 0.0
    assert ring_kernel(0.452 * R, R) < 0.0 < ring_kernel(0.450 * R, R)  # the outer slag holds the axis back
    with pytest.raises(ValueError, match=r"radius = 0.0 m; allowed a distance > 0"):
        ring_kernel([0.0, 0.01], R)
    with pytest.raises(ValueError, match=r"column_radius = 0.0; allowed a finite number > 0 \[m\]"):
        ring_kernel(0.01, 0.0)
    with pytest.raises(ValueError, match=r"viscosity = -0.45; allowed a finite number > 0 \[Pa s\]"):
        stokes_axis_velocity([0.01], [1e-9], 0.01, R, -0.45, DRHO, 1e-3)


@pytest.mark.parametrize("shape", ["ring", "gaussian", "outer ring"])
def test_the_axis_velocity_matches_a_finite_difference_solution_of_the_confined_flow(shape):
    """Droplets placed as a thin ring at 10 mm, a Gaussian plume of 8 mm width and a ring at 40 mm (beyond the return
    radius: it pushes the axis up): u_K agrees with the finite-difference solution of the same load spread over
    rings within 0.3 %."""
    dz = 0.01
    if shape == "gaussian":
        r = np.linspace(1e-5, R, 20000)
        weight = np.exp(-0.5 * (r / 8e-3) ** 2) * r
    else:
        centre = 0.01 if shape == "ring" else 0.04
        r = np.linspace(centre - 1e-3, centre + 1e-3, 2001)
        weight = r.copy()
    volume = 1e-9 * weight / weight.sum()  # 1 mm^3 in the band
    got = stokes_axis_velocity(r, volume, dz, R, MU, DRHO, width=1e-8)  # spreading far below the rings' widths
    edges = np.linspace(0.0, R, 4001)
    load, _ = np.histogram(r, bins=edges, weights=volume)
    ring_area = math.pi * (edges[1:] ** 2 - edges[:-1] ** 2)
    density = DRHO * GRAVITY * load / (ring_area * dz)  # N/m^3

    def force(centres):
        return np.interp(centres, 0.5 * (edges[1:] + edges[:-1]), density)

    want = _finite_difference_axis_velocity(force, R)
    assert got == pytest.approx(want, rel=2e-4)
    assert (got < 0.0) == (shape == "outer ring")


@pytest.mark.parametrize("offset", [0.0, 1.0, 3.0])
def test_the_smoothed_kernel_matches_a_finite_difference_solution_of_a_gaussian_spread_force(offset):
    """One droplet's force spread over a Gaussian of sigma = 5 mm (the demo's cell, as the engine spreads it) around
    a point 0, 1 and 3 sigma off the axis: the axis velocity from the smoothed kernel agrees within 0.1 % with the
    finite-difference solution of the ring-averaged Gaussian force density F exp(-(rho^2 + r^2) / 2 sigma^2)
    I0(rho r / sigma^2) / (2 pi sigma^2); far from the axis (10 sigma) the smoothing only adds the Gaussian's own
    spread to K, 4 sigma^2 / R^2 (to 1e-9)."""
    from scipy.special import i0e

    sigma, dz, volume = 5e-3, 0.01, 1e-9
    r = offset * sigma
    got = stokes_axis_velocity([r], [volume], dz, R, MU, DRHO, sigma)
    line_force = DRHO * GRAVITY * volume / dz  # N/m

    def force(rho):
        return line_force / (2.0 * math.pi * sigma**2) * np.exp(-((rho - r) ** 2) / (2.0 * sigma**2)) \
            * i0e(rho * r / sigma**2)

    want = _finite_difference_axis_velocity(force, R)
    assert got == pytest.approx(want, rel=1e-3)
    far = 10.0 * sigma * np.array([1.0, 1.05])
    assert np.allclose(smoothed_ring_kernel(far, R, sigma) - ring_kernel(far, R), 4.0 * sigma**2 / R**2, atol=1e-9)


def test_a_constructed_plume_is_measured_band_by_band(tmp_path):
    """One snapshot of the demo (100 mm high, 5 mm cells): 300 droplets on a ring
    of 10 mm in the band 40-50 mm and 300 at 2-3 mm in the band 50-60 mm, the measured axis velocity there 30 and 20
    mm/s. u_K in each band is the smoothed kernel's sum at the engine's sigma = max(sigma_cells h, sigma_diameter d)
    (here one cell); the
    middle ratio is the mean velocity over the mean u_K of bands 4-7; loads are the droplets' volume over 10 mm; the
    stored table round-trips; a profile without the snapshot's time is refused by name."""
    rng = np.random.default_rng(7)
    d = 5e-4
    volume = math.pi / 6.0 * d**3
    radius = np.concatenate([np.full(300, 0.01), rng.uniform(2e-3, 3e-3, 300)])
    angle = rng.uniform(0.0, 2.0 * math.pi, 600)
    z = np.concatenate([rng.uniform(0.041, 0.049, 300), rng.uniform(0.051, 0.059, 300)])
    points = np.column_stack([0.05 + radius * np.cos(angle), 0.05 + radius * np.sin(angle), z])
    data = {"diameter": np.full(600, d), "velocity": np.zeros((600, 3)), "density": np.full(600, 5100.0),
            "age": np.zeros(600), "ident": np.arange(600, dtype=float), "merged": np.zeros(600)}
    folder = tmp_path / "run"
    _run_folder(folder, [(20.0, points, data)])
    centres = 0.5 * (band_edges(0.1)[:-1] + band_edges(0.1)[1:])
    axis = {0.045: 0.03, 0.055: 0.02}
    write_table([{"time": 20.0, "z": c, "channel_radius": math.nan,
                  "channel_velocity": next((u for k, u in axis.items() if abs(k - c) < 1e-9), 0.0),
                  "droplet_volume": 0.0} for c in centres], CHANNEL_PROFILE, folder / "channel_profile.csv")
    case = load_case("demo")
    column, mu, drho = column_radius(case), case.slag_viscosity, case.matte.density - case.slag.density
    table, meta = measure_plume_force(folder, (15.0, 20.0))
    assert meta["snapshots"] == [20.0]
    scale = drho * GRAVITY * volume / (0.01 * 4.0 * math.pi * mu)
    sigma = max(case.fulldem.sigma_cells * case.fulldem.cell_size, case.fulldem.sigma_diameter * d)
    ring = 300 * scale * smoothed_ring_kernel(0.01, column, sigma)
    inner = scale * smoothed_ring_kernel(radius[300:], column, sigma).sum()
    assert table["stokes_axis_velocity"].iloc[4] == pytest.approx(ring, rel=1e-9)
    assert table["stokes_axis_velocity"].iloc[5] == pytest.approx(inner, rel=1e-9)
    assert table["load"].iloc[4] == pytest.approx(300 * volume / 0.01, rel=1e-12)
    assert table.drop(index=[4, 5])["stokes_axis_velocity"].abs().sum() == 0.0
    assert meta["middle_ratio"] == pytest.approx(0.05 / (ring + inner), rel=1e-9)
    back, back_meta = read_plume_force(write_plume_force(folder, tmp_path, (15.0, 20.0)))
    assert back_meta["window"] == (15.0, 20.0) and back_meta["snapshots"] == [20.0]
    assert np.allclose(back.to_numpy(), table.to_numpy(), rtol=1e-6)
    assert back_meta["middle_ratio"] == pytest.approx(meta["middle_ratio"], rel=1e-6)
    write_table([{"time": 21.0, "z": c, "channel_radius": math.nan, "channel_velocity": 0.0, "droplet_volume": 0.0}
                 for c in centres], CHANNEL_PROFILE, folder / "channel_profile.csv")
    with pytest.raises(ValueError, match="channel_profile.csv: no row at the snapshot time 20 s"):
        measure_plume_force(folder, (15.0, 20.0))


@pytest.mark.parametrize("core", [0.004, 0.012, 0.03])
def test_the_equivalent_core_recovers_a_uniform_core_that_carries_the_feed_at_the_axis_speed(core):
    """A uniform core of radius a holding the feed Q at the axis speed u (load Q / u per height) drives u_K; the
    equivalent core of that table is a again (to the area-uniform ring quadrature, 1e-3), and f = u / u_K."""
    import pandas as pd

    from analysis.plume_force import MIDDLE_BANDS, equivalent_core, stokes_axis_velocity

    column, mu, drho, q, u, dz = 0.0564, 0.45, 1500.0, 2.15e-3 / 5000.0, 0.05, 0.01
    n = 4000
    radii = core * np.sqrt((np.arange(n) + 0.5) / n)  # area-uniform rings
    volume = np.full(n, q / u * dz / n)
    u_k = stokes_axis_velocity(radii, volume, dz, column, mu, drho, 1e-9)
    assert u_k == pytest.approx(q / u * drho * GRAVITY * confined_axis_coefficient(column / core) / (4 * math.pi * mu),
                                rel=1e-3)
    rows = max(MIDDLE_BANDS.stop, 10)
    table = pd.DataFrame({"z": np.arange(rows) * dz, "axis_velocity": np.full(rows, 0.8 * u_k),
                          "stokes_axis_velocity": np.full(rows, u_k), "load": np.full(rows, q / u)})
    # the measured axis 0.8 u_K: the load Q / u was set with u, so the core that drives 0.8 u_K at load Q / (0.8 u_K)
    # is the one whose A0 is W (0.8 u_K) / Q
    found = equivalent_core(table, q, column, mu, drho)
    assert found["force_factor"] == pytest.approx(0.8, rel=1e-12)
    w = u_k * 4 * math.pi * mu / (drho * GRAVITY)
    assert found["a0"] == pytest.approx(w * 0.8 * u_k / q, rel=1e-12)
    assert confined_axis_coefficient(column / found["core_radius"]) == pytest.approx(found["a0"], rel=1e-9)
    table["axis_velocity"] = u  # the axis at the speed the load was built with: the core itself comes back
    assert equivalent_core(table, q, column, mu, drho)["core_radius"] == pytest.approx(core, rel=1e-3)
    # droplets at half the axis speed: the same load is carried by an axis twice as fast (A0 = W t u / Q)
    table["axis_velocity"] = 2 * u
    assert equivalent_core(table, q, column, mu, drho, 0.5)["core_radius"] == pytest.approx(core, rel=1e-3)


def test_the_equivalent_core_refuses_a_non_positive_feed():
    import pandas as pd

    from analysis.plume_force import equivalent_core

    table = pd.DataFrame({"axis_velocity": np.ones(10), "stokes_axis_velocity": np.ones(10)})
    with pytest.raises(ValueError, match="feed_volume_rate"):
        equivalent_core(table, 0.0, 0.05, 0.45, 1500.0)
