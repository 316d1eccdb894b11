"""analysis.band_efficiency: the gravitational collisions of droplets cell by cell against the kernel
pi (a_i + a_j)^2 abs(U_i - U_j) n_i n_j V evaluated pair by pair, and a whole run's efficiency band by band as its
merges over those collisions."""

import math
import shutil

import numpy as np
import pytest

from analysis.band_efficiency import band_efficiency, cell_collision_rates


def _pairwise(position, diameter, velocity, cell, height, bands):
    """The same sum, pair by pair (the independent reference)."""
    index = np.floor(position / cell).astype(int)
    rates = np.zeros(bands)
    for i in range(len(diameter)):
        for j in range(i + 1, len(diameter)):
            if (index[i] == index[j]).all():
                band = min(int((index[i, 2] + 0.5) * cell / height * bands), bands - 1)
                rates[band] += math.pi * (0.5 * (diameter[i] + diameter[j])) ** 2 * abs(velocity[i] - velocity[j])
    return rates / cell**3


def test_two_droplets_in_one_cell_collide_at_the_kernels_rate_and_in_two_cells_not_at_all():
    d = np.array([0.5e-3, 1.0e-3])
    u = np.array([0.6e-3, 2.4e-3])
    cell = 5e-3
    together = np.array([[1e-3, 1e-3, 1e-3], [4e-3, 4e-3, 4e-3]])  # one cell, the bottom band of 4 over 20 mm
    rates = cell_collision_rates(together, d, u, cell, 0.02, 4)
    expected = math.pi * (0.75e-3) ** 2 * 1.8e-3 / cell**3
    assert rates == pytest.approx([expected, 0.0, 0.0, 0.0], rel=1e-12)
    apart = together + np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 2e-3]])  # the second one cell up
    assert cell_collision_rates(apart, d, u, cell, 0.02, 4).sum() == 0.0


def test_cell_sums_match_the_pairwise_kernel_for_random_droplets():
    """400 droplets of 0.3-1 mm with random velocities in a 20 mm cube of 5 mm cells, 4 bands, and 20 mm cells (one
    band per cell column): the sorted prefix sums equal the double loop to round-off."""
    rng = np.random.default_rng(7)
    position = rng.uniform(0.0, 0.02, (400, 3))
    diameter = rng.uniform(0.3e-3, 1.0e-3, 400)
    velocity = rng.normal(0.0, 1e-3, 400)
    for cell, bands in ((5e-3, 4), (1e-2, 2), (2e-2, 1)):
        fast = cell_collision_rates(position, diameter, velocity, cell, 0.02, bands)
        assert fast == pytest.approx(_pairwise(position, diameter, velocity, cell, 0.02, bands), rel=1e-10)
        assert (fast > 0).all()
    with pytest.raises(ValueError, match="cell = 0"):
        cell_collision_rates(position, diameter, velocity, 0.0, 0.02)


def test_a_runs_efficiency_is_its_merges_over_the_collisions_of_its_snapshot(tmp_path):
    """The stored demo (snapshots at 13 and 25 s) given a merge table: 120 merges in the top band and 30 in the
    bottom band between 20 and 25 s. Only the 25 s snapshot lies in that window, so the collisions are its rates
    (cell_collision_rates with the droplets' terminal velocities) times 5 s, and each band's efficiency follows."""
    from analysis.runs import load_run
    from settler.derived import settling_velocity
    from settler.output import MERGES_BY_HEIGHT, PROFILE_BANDS, write_table

    folder = tmp_path / "demo"
    shutil.copytree("data/reference/demo", folder)
    height = 0.1
    z = (np.arange(PROFILE_BANDS) + 0.5) * height / PROFILE_BANDS
    rows = []
    for t, top, bottom in ((20.0, 0.0, 0.0), (25.0, 120.0, 30.0)):
        for k, zk in enumerate(z):
            rows.append({"time": t, "z": zk, "merges_under_inlet": top if k == PROFILE_BANDS - 1 else 0.0,
                         "merges_elsewhere": bottom if k == 0 else 0.0})
    write_table(rows, MERGES_BY_HEIGHT, folder / "merges_by_height.csv")
    result = band_efficiency(folder, (20.0, 25.0))
    assert result["window"] == (20.0, 25.0) and result["snapshots"] == [25.0] and result["cell"] == 0.005

    run = load_run(folder)
    _, d = run.droplets(25.0)
    u = settling_velocity(run.case, d["diameter"].to_numpy(), d["density"].to_numpy())
    rates = cell_collision_rates(d[["x", "y", "z"]].to_numpy(), d["diameter"].to_numpy(), u, 0.005, height)
    bands = result["bands"]
    assert bands["collisions"].to_numpy() == pytest.approx(rates * 5.0, rel=1e-12)
    assert bands["efficiency"].iloc[-1] == pytest.approx(120.0 / (rates[-1] * 5.0), rel=1e-12)
    assert bands["efficiency"].iloc[0] == pytest.approx(30.0 / (rates[0] * 5.0), rel=1e-12)
    assert result["efficiency"] == pytest.approx(150.0 / (rates.sum() * 5.0), rel=1e-12)
    assert result["standard_error"] == pytest.approx(result["efficiency"] / math.sqrt(150.0), rel=1e-12)
    assert bands["held"].sum() == len(d)
    # well mixed by region: the top band's merges were all under the inlet, the bottom band's all elsewhere
    assert result["mixed"]["under_inlet"] == pytest.approx(120.0 / bands["collisions_under_inlet"].sum(), rel=1e-12)
    assert result["mixed"]["elsewhere"] == pytest.approx(30.0 / bands["collisions_elsewhere"].sum(), rel=1e-12)
    assert bands["efficiency_under_inlet"].iloc[0] == 0.0  # droplets there, no merges
    top_elsewhere = bands["collisions_elsewhere"].iloc[-1]  # the demo's top band holds droplets under the inlet only
    assert (top_elsewhere == 0.0 and math.isnan(bands["efficiency_elsewhere"].iloc[-1])) or \
        bands["efficiency_elsewhere"].iloc[-1] == 0.0
    for row in rows:  # the same merges a second earlier: the window 20-21 s holds no snapshot
        row["time"] = 21.0 if row["time"] == 25.0 else row["time"]
    write_table(rows, MERGES_BY_HEIGHT, folder / "merges_by_height.csv")
    with pytest.raises(ValueError, match="no droplet snapshot within 20-21 s"):
        band_efficiency(folder, (20.0, 21.0))


def test_well_mixed_regions_give_the_uniform_suspension_kernel():
    """Two sizes in one band's two regions: the region rate is pi (a_s + a_l)^2 abs(dU) N_s N_l / V_region whatever
    the droplets' places inside it (the pair sum of a well-mixed zone), equal sizes add nothing, and a band's
    regions do not see each other's droplets."""
    from analysis.band_efficiency import region_collision_rates

    d = np.array([0.5e-3] * 3 + [1.0e-3] * 2 + [0.5e-3] * 4)
    u = np.where(d < 0.7e-3, 0.6e-3, 2.4e-3)
    band = np.array([1, 1, 1, 1, 0, 0, 0, 0, 0])  # band 1 under the inlet: 3 small, 1 large; band 0 elsewhere: 1, 4
    under = np.array([True] * 4 + [False] * 5)
    volumes = np.array([[2e-6, 6e-6], [2e-6, 6e-6]])
    rates = region_collision_rates(band, under, d, u, volumes)
    expected = math.pi * (0.75e-3) ** 2 * 1.8e-3 * 3 * 1 / 2e-6
    assert rates[1, 0] == pytest.approx(expected, rel=1e-12)
    assert rates[0, 1] == pytest.approx(math.pi * (0.75e-3) ** 2 * 1.8e-3 * 4 / 6e-6, rel=1e-12)
    assert rates[1, 1] == 0.0 and rates[0, 0] == 0.0
