"""analysis.band_efficiency: the gravitational collisions of droplets cell by cell against the kernel
pi (a_i + a_j)^2 abs(U_i - U_j) n_i n_j V evaluated pair by pair, and a whole run's efficiency band by band as its
merges over those collisions."""

import math
import shutil

import numpy as np
import pandas as pd
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
    result = band_efficiency(load_run(folder), (20.0, 25.0))  # a Run: the stored snapshots stand in for a run's
    assert result["window"] == (20.0, 25.0) and result["snapshots"] == [25.0] and result["cell"] == 0.005
    assert result["kernels"] is None  # a stored reference keeps one plane of the slag: no shear rates

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
    assert result["mixed"]["under_inlet"] == pytest.approx(120.0 / bands["mixed_under_inlet"].sum(), rel=1e-12)
    assert result["mixed"]["elsewhere"] == pytest.approx(30.0 / bands["mixed_elsewhere"].sum(), rel=1e-12)
    assert bands["efficiency_under_inlet"].iloc[0] == 0.0  # droplets there, no merges
    top_elsewhere = bands["mixed_elsewhere"].iloc[-1]  # the demo's top band holds droplets under the inlet only
    assert (top_elsewhere == 0.0 and math.isnan(bands["efficiency_elsewhere"].iloc[-1])) or \
        bands["efficiency_elsewhere"].iloc[-1] == 0.0
    for row in rows:  # the same merges a second earlier: the window 20-21 s holds no snapshot
        row["time"] = 21.0 if row["time"] == 25.0 else row["time"]
    write_table(rows, MERGES_BY_HEIGHT, folder / "merges_by_height.csv")
    with pytest.raises(ValueError, match="no droplet snapshot within 20-21 s"):
        band_efficiency(load_run(folder), (20.0, 21.0))


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


def test_well_mixed_shear_is_smoluchowskis_kernel():
    """N equal droplets of radius a well mixed in a region of volume V sheared at G meet (4/3) G (2a)^3 N (N - 1) / 2
    / V times a second (Smoluchowski's simple-shear rate, beta n^2 V / 2 with beta = (4/3) G (2a)^3 and n = N / V,
    counting each pair once); a region with one droplet meets nobody even where its shear is unknown (NaN)."""
    from analysis.band_efficiency import region_shear_rates

    d = np.array([0.6e-3] * 7 + [0.7e-3])  # 0.7 mm: n S3 + 3 S1 S2 - 4 S3 leaves a rounding residue for one droplet
    band = np.array([0] * 7 + [1])
    under = np.array([True] * 7 + [False])
    shear = np.array([[3.0, 0.5], [0.2, np.nan]])
    volumes = np.array([[2e-6, 6e-6], [2e-6, 6e-6]])
    rates = region_shear_rates(band, under, d, shear, volumes)
    assert rates[0, 0] == pytest.approx(4.0 / 3.0 * 3.0 * (0.6e-3) ** 3 * 7 * 6 / 2 / 2e-6, rel=1e-12)
    assert rates[1, 1] == 0.0 and rates[0, 1] == 0.0 and rates[1, 0] == 0.0


def test_shear_pair_sums_match_the_pairwise_sum():
    from analysis.band_efficiency import shear_pair_sums

    rng = np.random.default_rng(3)
    group = rng.integers(0, 5, 60)
    diameter = rng.uniform(0.3e-3, 1.2e-3, 60)
    keys, sums = shear_pair_sums(group, diameter)
    for key, value in zip(keys, sums):
        a = 0.5 * diameter[group == key]
        brute = sum((a[i] + a[j]) ** 3 for i in range(len(a)) for j in range(i + 1, len(a)))
        assert value == pytest.approx(brute, rel=1e-12)


def test_shear_rate_of_a_simple_shear_and_of_a_rotation():
    """u = G z gives G in every cell (central and one-sided differences are exact for a linear field); a solid-body
    rotation has no strain; a single plane of cells is refused."""
    from analysis.band_efficiency import cell_shear_rates

    h = 5e-3
    x, y, z = np.meshgrid(*(np.arange(n) * h + h / 2 for n in (4, 3, 5)), indexing="ij")
    centres = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    rng = np.random.default_rng(0)
    shuffled = rng.permutation(len(centres))  # the snapshot's cell order does not matter
    simple = np.column_stack([2.5 * centres[:, 2], np.zeros(len(centres)), np.zeros(len(centres))])
    rate, edge = cell_shear_rates(centres[shuffled], simple[shuffled])
    assert edge == pytest.approx(h) and rate.shape == (4, 3, 5) and rate == pytest.approx(np.full((4, 3, 5), 2.5))
    rotation = np.column_stack([-centres[:, 1], centres[:, 0], np.zeros(len(centres))]) * 3.0
    assert cell_shear_rates(centres, rotation)[0] == pytest.approx(np.zeros((4, 3, 5)), abs=1e-12)
    plane = centres[centres[:, 1] == centres[0, 1]]
    with pytest.raises(ValueError, match="three-dimensional grid"):
        cell_shear_rates(plane, np.zeros_like(plane))


def test_kernel_fit_recovers_known_efficiencies():
    """Merges made exactly as 1.0 C_g + 0.6 C_s over regions where the two kernels weigh differently: both
    recovered, chi-square 0; Poisson-scattered merges: recovered within the reported standard errors (3 sigma)."""
    from analysis.band_efficiency import kernel_fit

    rng = np.random.default_rng(11)
    grav = rng.uniform(1e3, 2e4, (10, 2))
    shear = grav * rng.uniform(0.05, 2.0, (10, 2))
    exact = kernel_fit(1.0 * grav + 0.6 * shear, grav, shear)
    assert (exact["gravitational"], exact["shear"]) == pytest.approx((1.0, 0.6), rel=1e-9)
    assert exact["chi2_reduced"] < 1e-12 and exact["regions"] == 20
    noisy = kernel_fit(rng.poisson(1.0 * grav + 0.6 * shear), grav, shear)
    se = noisy["standard_errors"]
    assert abs(noisy["gravitational"] - 1.0) < 3 * se[0] and abs(noisy["shear"] - 0.6) < 3 * se[1]
    assert -1.0 < noisy["correlation"] < 0.0  # the two kernels trade off against each other
    proportional = kernel_fit(grav + shear, grav, 2.0 * grav)  # nothing tells the two apart
    assert math.isnan(proportional["gravitational"]) and proportional["regions"] == 20


def test_collisions_file_round_trips_and_a_stored_reference_reads_it(tmp_path):
    """write_collisions measures a run (here the stored demo given a merge table, as a stand-in for a run folder)
    and a stored reference that keeps the file gives back the same efficiencies from it, without measuring."""
    from analysis.band_efficiency import COLLISIONS_FILE, measure_collisions, read_collisions, write_collisions
    from analysis.runs import load_run
    from settler.output import MERGES_BY_HEIGHT, PROFILE_BANDS, write_table

    folder = tmp_path / "demo"
    # the stored demo without its own merge and collision tables (a remade run keeps both)
    shutil.copytree("data/reference/demo", folder,
                    ignore=shutil.ignore_patterns(COLLISIONS_FILE, "merges_by_height.csv"))
    z = (np.arange(PROFILE_BANDS) + 0.5) * 0.01
    rows = [{"time": t, "z": zk, "merges_under_inlet": n * (k + 1), "merges_elsewhere": n}
            for t, n in ((10.0, 0.0), (25.0, 3.0)) for k, zk in enumerate(z)]
    write_table(rows, MERGES_BY_HEIGHT, folder / "merges_by_height.csv")
    run = load_run(folder)  # a Run: the stored snapshots stand in for a run folder's
    measured = band_efficiency(run)
    path = write_collisions(run, folder)
    table, meta = read_collisions(path)
    fresh, fresh_meta = measure_collisions(run)
    pd.testing.assert_frame_equal(table, fresh, rtol=1e-8, check_dtype=False)
    assert meta["window"] == fresh_meta["window"] and meta["snapshots"] == fresh_meta["snapshots"]
    assert meta["cell"] == 0.005 and meta["rate_scatter"] == pytest.approx(fresh_meta["rate_scatter"], rel=1e-12)
    (folder / "merges_by_height.csv").unlink()  # the file alone now answers
    stored = band_efficiency(folder)
    assert stored["efficiency"] == pytest.approx(measured["efficiency"], rel=1e-8)
    assert stored["standard_error"] == pytest.approx(measured["standard_error"], rel=1e-8)
    assert stored["mixed"] == pytest.approx(measured["mixed"], rel=1e-8) and stored["kernels"] is None
    # asked for the file's own window (as the evidence report asks, with the run's steady window), the file answers
    # too, not the one or two snapshots the reference keeps inside the window
    again = band_efficiency(folder, meta["window"])
    assert again["efficiency"] == pytest.approx(measured["efficiency"], rel=1e-8)
    assert again["snapshots"] == meta["snapshots"]
    assert (folder / COLLISIONS_FILE).read_text().startswith("# units: z [m], held [-]")


def test_shear_rate_and_volume_held_at_the_droplets_band_by_band():
    """A stand-in run (the demo case, 0.1 m cube, 5 mm cells) whose slag is the simple shear u_x = G y with G = 2
    1/s in every cell, and six droplets of known sizes: three under the inlet in the top band, two elsewhere in the
    bottom band, one under the inlet in the bottom band. Every droplet sees G = 2 1/s (central and one-sided
    differences are exact for a linear field), so each band and place that holds droplets averages 2 and the others
    are NaN; the volume held is (pi/6) d^3 summed by band and place, the same at both snapshots."""
    from types import SimpleNamespace

    from analysis.band_efficiency import measure_collisions
    from settler.cases import load_case
    from settler.output import PROFILE_BANDS

    case = load_case("demo")
    g = case.geometry
    h = 5e-3
    axes = [np.arange(n) * h + h / 2 for n in (round(g.width / h), round(g.depth / h), round(g.height / h))]
    x, y, z = np.meshgrid(*axes, indexing="ij")
    centres = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    slag = np.column_stack([2.0 * centres[:, 1], np.zeros(len(centres)), np.zeros(len(centres))])
    cx, cy = case.inlet_center[0], case.inlet_center[1]
    far = (0.01, 0.01)  # a corner, outside the inlet disk
    top, bottom = 0.095, 0.004
    droplets = pd.DataFrame({"x": [cx, cx + 1e-3, cx - 1e-3, far[0], far[0] + 0.02, cx],
                             "y": [cy, cy, cy + 1e-3, far[1], far[1], cy],
                             "z": [top, top, top + 1e-3, bottom, bottom, bottom],
                             "diameter": [1.0e-3, 0.5e-3, 0.8e-3, 0.6e-3, 0.7e-3, 0.9e-3]})
    droplets["density"] = case.matte.density
    bands_z = (np.arange(PROFILE_BANDS) + 0.5) * g.height / PROFILE_BANDS
    merges = pd.DataFrame([{"time": t, "z": zk, "merges_under_inlet": 0.0, "merges_elsewhere": 0.0}
                           for t in (1.0, 2.0) for zk in bands_z])
    run = SimpleNamespace(case=case, folder="stand-in", zones={"merges_by_height": merges},
                          timeseries=pd.DataFrame({"time": [0.0, 1.0, 2.0], "droplet_count": [6, 6, 6]}),
                          snapshot_times=lambda: [1.0, 2.0], droplets=lambda t: (t, droplets),
                          slag=lambda t: (t, centres, slag))
    table, meta = measure_collisions(run, (1.0, 2.0))
    assert meta["snapshots"] == [1.0, 2.0]
    volume = math.pi / 6.0 * droplets["diameter"].to_numpy() ** 3
    expected = np.zeros((PROFILE_BANDS, 2))
    expected[-1, 0] = volume[:3].sum()
    expected[0, 1] = volume[3:5].sum()
    expected[0, 0] = volume[5]
    assert table[["volume_under_inlet", "volume_elsewhere"]].to_numpy() == pytest.approx(expected, rel=1e-12)
    rate = table[["shear_rate_under_inlet", "shear_rate_elsewhere"]].to_numpy()
    held = expected > 0
    assert rate[held] == pytest.approx(np.full(held.sum(), 2.0), rel=1e-9)
    assert np.isnan(rate[~held]).all()
    # well mixed and sheared at G = 2 1/s: (4/3) G sum over each region's pairs of (a_i + a_j)^3 / V_region, over
    # the 1 s window; the lone droplet under the inlet in the bottom band meets nobody
    a = 0.5 * droplets["diameter"].to_numpy()
    inlet_area = math.pi * (0.5 * g.inlet_diameter) ** 2
    band_height = g.height / PROFILE_BANDS
    pairs_top = (a[0] + a[1]) ** 3 + (a[0] + a[2]) ** 3 + (a[1] + a[2]) ** 3
    mixed = table[["mixed_shear_under_inlet", "mixed_shear_elsewhere"]].to_numpy()
    assert mixed[-1, 0] == pytest.approx(4.0 / 3.0 * 2.0 * pairs_top / (band_height * inlet_area), rel=1e-9)
    assert mixed[0, 1] == pytest.approx(4.0 / 3.0 * 2.0 * (a[3] + a[4]) ** 3
                                        / (band_height * (g.width * g.depth - inlet_area)), rel=1e-9)
    assert mixed[0, 0] == 0.0 and (mixed[1:-1] == 0.0).all()
