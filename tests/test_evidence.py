"""analysis.evidence on constructed data with known answers: the steady rule on a ramp followed by exact burst
cycles, the rim test on a core and a ring, and the collision efficiency of a uniform two-size suspension against the
gravitational kernel pi (a_s + a_l)^2 |dU| n_s n_l V."""

import math

import numpy as np
import pandas as pd
import pytest

from analysis.evidence import collision_efficiency, pair_exposure, rim_share, seed_scatter, steady_means, steady_window


def _bursting(ramp_end=13.0, amplitude=0.07, end=45.0):
    t = np.round(np.arange(0.0, end + 1e-9, 0.1), 10)
    y = 1e5 * np.minimum(t / ramp_end, 1.0) * (1.0 + amplitude * np.sin(2 * np.pi * t / 5.0))
    return pd.DataFrame({"time": t, "droplet_count": y})


def test_steady_window_starts_at_the_first_whole_cycle_after_the_rise():
    window = steady_window(_bursting())
    # blocks back from 45 s: (10, 15] holds the ramp's end (mean 3 % low), (15, 20] ... (40, 45] are exact cycles
    assert window["start"] == pytest.approx(15.0) and window["cycles"] == 6
    assert window["mean"] == pytest.approx(1e5, rel=1e-9) and window["spread"] < 1e-9
    # a rise that never ends is not steady
    rising = _bursting()
    rising["droplet_count"] *= 1 + rising["time"] / 45.0
    assert math.isnan(steady_window(rising)["start"])
    means = steady_means(_bursting(), ["droplet_count"], 15.0)
    assert means["droplet_count"] == pytest.approx(1e5, rel=1e-9)
    assert seed_scatter({"a": 2.0}, {"a": 2.1})["a"] == pytest.approx(0.05)


def test_rim_share_of_a_core_and_a_ring():
    rng = np.random.default_rng(1)
    core = pd.DataFrame({"x": rng.uniform(-1e-3, 1e-3, 100), "y": rng.uniform(-1e-3, 1e-3, 100), "z": 0.2,
                         "diameter": 1e-3, "age": 1.0, "merged": 1.0})
    angle = np.linspace(0, 2 * np.pi, 10, endpoint=False)
    ring = pd.DataFrame({"x": 0.01 * np.cos(angle), "y": 0.01 * np.sin(angle), "z": 0.2, "diameter": 1e-3,
                         "age": [100.0] * 4 + [1.0] * 6, "merged": [0.0] * 4 + [1.0] * 6})
    below = ring.assign(z=0.05, merged=0.0, age=100.0)  # outside the band: ignored
    result = rim_share(pd.concat([core, ring, below]), (0.0, 0.0), 0.15, 0.35)
    assert result["outside"] == 10 and result["rim"] == 4 and result["share"] == pytest.approx(0.4)
    assert result["median_age"] == 1.0 and result["half_volume_radius"] < 2e-3


def test_collision_efficiency_of_a_uniform_suspension():
    ds, dl, us, ul = 0.5e-3, 1.0e-3, 0.6e-3, 2.5e-3
    area, height, ns, nl = 0.01, 0.08, 3000, 2000
    rng = np.random.default_rng(2)
    snapshots = []
    for time in np.arange(0.0, 10.01, 0.5):
        z = rng.uniform(0.0, height, ns + nl)
        # one 0.08 m slice: N_s N_l / V exactly, whatever the positions
        snapshots.append((time, pd.DataFrame({"z": z, "diameter": [ds] * ns + [dl] * nl,
                                              "settling_velocity": [us] * ns + [ul] * nl})))
    exposure = pair_exposure(snapshots, (0.4e-3, 0.6e-3), (0.9e-3, 1.1e-3), area, height)
    expected = math.pi * (0.75e-3) ** 2 * (ul - us) * ns * nl / (area * height) * 10.0
    result = collision_efficiency(round(0.5 * expected), exposure, ds, dl)
    assert result["expected_collisions"] == pytest.approx(expected, rel=1e-12)
    assert result["efficiency"] == pytest.approx(0.5, abs=1.0 / expected)
    assert result["standard_error"] == pytest.approx(0.5 / math.sqrt(round(0.5 * expected)), rel=0.01)


def test_collision_efficiency_counts_droplets_placed_at_rest_at_their_terminal_velocity():
    """The initial snapshot (every droplet at rest) takes the next snapshot's velocity difference: droplets reach
    terminal velocity in ~1 ms, so the first interval must count its full collisions (uniform suspension, where
    the expected count is analytic); a constant rate has no quadrature error."""
    ds, dl, us, ul = 0.5e-3, 1.0e-3, 0.6e-3, 2.5e-3
    area, height, ns, nl = 0.01, 0.08, 300, 200
    snapshots = []
    for time in np.arange(0.0, 10.01, 0.5):
        u_small, u_large = (0.0, 0.0) if time == 0.0 else (us, ul)
        snapshots.append((time, pd.DataFrame({"z": np.full(ns + nl, 0.04), "diameter": [ds] * ns + [dl] * nl,
                                              "settling_velocity": [u_small] * ns + [u_large] * nl})))
    exposure = pair_exposure(snapshots, (0.4e-3, 0.6e-3), (0.9e-3, 1.1e-3), area, height)
    expected = math.pi * (0.75e-3) ** 2 * (ul - us) * ns * nl / (area * height) * 10.0
    result = collision_efficiency(100, exposure, ds, dl)
    assert result["expected_collisions"] == pytest.approx(expected, rel=1e-12)
    assert result["quadrature_error"] == pytest.approx(0.0, abs=1e-9)


def test_stored_kernel_runs_give_their_efficiency_at_their_own_sizes():
    """Each stored kernel run's efficiency is computed at the sizes its exposure file records (0.5/1.0 mm and
    0.35/1.4 mm), equal to the efficiency with those sizes given; the velocity difference of the pair is within 25 %
    of the Stokes difference of the two sizes in the demo's slag (hindered and wall-slowed, never faster)."""
    from analysis.kernel_run import kernel_run_efficiency
    from settler.cases import DATA_DIR, load_case
    from settler.physics import stokes_velocity

    for run, sizes in (("kernel", (0.5e-3, 1.0e-3)), ("kernel_ratio4", (0.35e-3, 1.4e-3))):
        folder = DATA_DIR / "reference" / run
        read = kernel_run_efficiency(folder)
        given = kernel_run_efficiency(folder, *sizes)
        assert read["sizes"] == pytest.approx(sizes) and read["efficiency"] == pytest.approx(given["efficiency"])
        case = load_case(folder / "case.toml")
        stokes = (stokes_velocity(sizes[1], case.matte.density, case.slag.density, case.slag_viscosity)
                  - stokes_velocity(sizes[0], case.matte.density, case.slag.density, case.slag_viscosity))
        assert 0.75 * stokes < read["velocity_difference"] <= 1.02 * stokes, (run, read["velocity_difference"], stokes)


def test_seed_scatter_of_runs_of_different_lengths_is_taken_over_their_common_span():
    """Two runs of one seed (equal series) where the first goes on to 75 s and its count keeps rising after 30 s:
    over their common span the scatter of every column is 0 to round-off, where comparing each run's own window
    (the first's 50-75 s against the second's 20-30 s) would report the rise, +50 % here, as seed scatter."""
    from analysis.evidence import STEADY_COLUMNS, pair_scatter

    t = np.arange(0.0, 75.05, 0.1)
    count = np.where(t < 10.0, 1000.0 * t / 10.0, 1000.0) * np.where(t > 30.0, 1.0 + (t - 30.0) / 45.0 * 0.8, 1.0)
    first = pd.DataFrame({"time": t, **{c: 1.0 + 0.0 * t for c in STEADY_COLUMNS}, "droplet_count": count})
    second = first[first["time"] <= 30.0 + 1e-9].copy()
    window, scatter = pair_scatter(first, second)
    assert window[1] == pytest.approx(30.0) and window[0] >= 10.0
    assert scatter and all(abs(v) < 1e-12 for v in scatter.values())
    own = first[first["time"] > 50.0]["droplet_count"].mean() / second[second["time"] > 20.0]["droplet_count"].mean()
    assert own - 1.0 > 0.4


def test_height_bands_count_a_full_runs_droplets_by_band():
    from types import SimpleNamespace

    from analysis.evidence import height_bands
    z = np.array([0.001, 0.005, 0.0099, 0.02, 0.05, 0.0901, 0.0999])  # 3 in the bottom 10 mm, 2 in the top
    run = SimpleNamespace(engine="fulldem", case=SimpleNamespace(geometry=SimpleNamespace(height=0.1)),
                          snapshot_times=lambda: [5.0, 12.0], droplets=lambda t: (t, pd.DataFrame({"z": z})))
    bands = height_bands(run)
    assert (bands["time"], bands["bottom"], bands["middle"], bands["top"], bands["total"]) == (12.0, 3, 2, 2, 7)
    assert height_bands(run, band=0.02)["bottom"] == 3 and height_bands(run, band=0.02)["top"] == 2
    with pytest.raises(ValueError, match="band = 0.06"):
        height_bands(run, band=0.06)


def test_height_bands_of_a_popbal_run_add_up_to_its_count(tmp_path):
    """popbal's number densities times zone area and cell height, summed over the bands, are the droplet count its
    time series reports (a different sum of the same state: sections first)."""
    from analysis import load_run
    from analysis.evidence import height_bands
    from settler.cli import main
    assert main(["reduced", "demo", "--end-time", "4", "--output-interval", "1", "--out", str(tmp_path / "r"),
                 "--quiet"]) == 0
    run = load_run(tmp_path / "r")
    for t in (2.0, 4.0):
        bands = height_bands(run, t)
        count = run.timeseries.set_index("time").loc[t, "droplet_count"]
        assert bands["time"] == t and bands["total"] == pytest.approx(count, rel=1e-9)
        assert bands["top"] > 0 and bands["middle"] > 0 and bands["bottom"] >= 0


def test_height_bands_command_prints_each_snapshot_and_refuses_an_unreadable_run(tmp_path, capsys):
    from analysis.evidence import main
    assert main(["--height-bands", "data/reference/demo"]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines()[1:]]
    assert [float(r[2]) for r in rows] == [13.0, 25.0] and all(int(r[3]) + int(r[4]) + int(r[5]) == int(r[6])
                                                                 for r in rows)
    assert main(["--height-bands", str(tmp_path / "none")]) == 2
    assert "no such run folder" in capsys.readouterr().err


def test_floor_arrivals_of_placed_droplets_by_ring():
    """Droplets placed in and above a 1 mm floor layer, in the three rings around the inlet axis, at known vertical
    velocities: counts, mean velocities, the terminal velocity of their size (settler.derived, the Stokes law at
    the demo's Reynolds numbers: (rho_p - rho_s) g d^2 / (18 mu) within 1 %), the ratio and the arrival rate
    count x (-w) / layer."""
    from types import SimpleNamespace

    from analysis.evidence import floor_arrivals
    from settler.cases import load_case
    case = load_case("demo")
    cx, cy = case.inlet_center
    d = 0.5e-3
    frame = pd.DataFrame({"x": [cx + 0.001, cx, cx + 0.010, cx + 0.030, cx + 0.030, cx],
                          "y": [cy, cy + 0.002, cy, cy, cy + 0.004, cy],
                          "z": [0.0002, 0.0008, 0.0005, 0.0001, 0.0009, 0.003],  # the last above the layer
                          "w": [-0.020, -0.010, -0.006, -0.001, 0.001, -0.050],
                          "diameter": d, "density": case.matte.density})
    run = SimpleNamespace(engine="fulldem", case=case, snapshot_times=lambda: [25.0],
                          droplets=lambda t: (t, frame))
    rings = floor_arrivals(run)
    assert [r["count"] for r in rings] == [2, 1, 2]
    assert [r["velocity"] for r in rings] == pytest.approx([-0.015, -0.006, 0.0], abs=1e-15)
    stokes = (case.matte.density - case.slag.density) * 9.80665 * d**2 / (18.0 * case.slag_viscosity)
    assert rings[0]["settling_velocity"] == pytest.approx(stokes, rel=0.01)
    assert rings[0]["ratio"] == pytest.approx(0.015 / rings[0]["settling_velocity"], rel=1e-12)
    assert [r["arrival_rate"] for r in rings] == pytest.approx([2 * 0.015 / 1e-3, 0.006 / 1e-3, 0.0], rel=1e-12)
    with pytest.raises(ValueError, match="rings"):
        floor_arrivals(run, rings=(0.015, 0.005))


def test_floor_command_prints_the_rings_of_a_stored_run(capsys):
    from analysis.evidence import main
    assert main(["--floor", "data/reference/demo"]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines()[1:]]
    assert [r[2] for r in rows] == ["0-5", "5-15", ">15"] and all(r[1] == "25" for r in rows)
    assert main(["--floor", "data/reference/none"]) == 2


def test_merge_shares_of_a_table_with_known_counts(tmp_path):
    """merge_shares: the merges between the rows nearest the window are the differences of the cumulative table, by
    band and place, and the shares follow; a run without the table or a window inside one snapshot is refused."""
    from analysis.evidence import merge_shares
    from settler.output import MERGES_BY_HEIGHT, PROFILE_BANDS, write_table

    folder = tmp_path / "run"
    folder.mkdir()
    pd.DataFrame({"time": [0.0, 1.0, 2.0], "droplet_count": [1.0, 2.0, 3.0]}).to_csv(folder / "timeseries.csv",
                                                                                   index=False)
    z = (np.arange(PROFILE_BANDS) + 0.5) * 0.01
    under = {0.0: np.zeros(PROFILE_BANDS), 1.0: np.arange(PROFILE_BANDS) * 1.0,
             2.0: np.arange(PROFILE_BANDS) * 1.0 + np.eye(PROFILE_BANDS)[-1] * 30.0}
    elsewhere = {0.0: np.zeros(PROFILE_BANDS), 1.0: np.full(PROFILE_BANDS, 2.0),
                 2.0: np.full(PROFILE_BANDS, 2.0) + np.eye(PROFILE_BANDS)[0] * 10.0}
    rows = [{"time": t, "z": zk, "merges_under_inlet": under[t][k], "merges_elsewhere": elsewhere[t][k]}
            for t in (0.0, 1.0, 2.0) for k, zk in enumerate(z)]
    write_table(rows, MERGES_BY_HEIGHT, folder / "merges_by_height.csv")
    m = merge_shares(folder, (0.9, 2.1))  # rows 1.0 and 2.0: 30 in the top band under the inlet, 10 at the bottom
    assert m["window"] == (1.0, 2.0) and m["merges"] == 40.0 and m["rate"] == 40.0
    assert (m["under_inlet"], m["top"], m["bottom"]) == (0.75, 0.75, 0.25)
    assert m["bands"]["merges_under_inlet"].tolist() == [0.0] * (PROFILE_BANDS - 1) + [30.0]
    m = merge_shares(folder, (0.0, 1.0))
    assert m["merges"] == sum(range(PROFILE_BANDS)) + 2.0 * PROFILE_BANDS and m["top"] == pytest.approx(
        (PROFILE_BANDS - 1 + 2.0) / m["merges"])
    with pytest.raises(ValueError, match="no two merges_by_height rows"):
        merge_shares(folder, (1.1, 1.2))
    (folder / "merges_by_height.csv").unlink()
    with pytest.raises(ValueError, match="no merges_by_height.csv"):
        merge_shares(folder)


def test_merge_shares_of_a_popbal_run_are_its_booked_merges(tmp_path):
    """A popbal run saved and read back: merge_shares over 5-10 s holds the merges popbal booked in that time (its
    distribution array and its time series' column alike), to the CSV's precision."""
    import popbal
    from analysis.evidence import merge_shares

    result = popbal.run(popbal.setup("demo", popbal__end_time=10), progress=False)
    result.save(tmp_path / "run")
    m = merge_shares(tmp_path / "run", (5.0, 10.0))
    t = result.arrays["time"]
    booked = result.arrays["merges"][t == 10.0].sum() - result.arrays["merges"][t == 5.0].sum()
    assert m["merges"] == pytest.approx(booked, rel=1e-6) and booked > 0.0
    assert m["merges"] == pytest.approx(result.timeseries.set_index("time")["merges"].loc[5.5:10.0].sum(), rel=1e-6)


def test_report_says_where_a_run_with_the_merge_table_merges(tmp_path):
    """The report's merges line for a stored run given a merges_by_height.csv: 100 merges in the top band under the
    inlet and 100 elsewhere in the bottom band between the table's first and last rows, over a window that holds
    both (the stored demo's steady window, about 16.7-25 s)."""
    import shutil

    from analysis.evidence import report
    from settler.output import MERGES_BY_HEIGHT, PROFILE_BANDS, write_table

    root = tmp_path / "reference"
    shutil.copytree("data/reference/demo", root / "demo")
    z = (np.arange(PROFILE_BANDS) + 0.5) * 0.01
    rows = []
    for t, n in ((10.0, 0.0), (25.0, 100.0)):
        for k, zk in enumerate(z):
            rows.append({"time": t, "z": zk, "merges_under_inlet": n if k == PROFILE_BANDS - 1 else 0.0,
                         "merges_elsewhere": n if k == 0 else 0.0})
    write_table(rows, MERGES_BY_HEIGHT, root / "demo" / "merges_by_height.csv")
    line = next(x for x in report(root).splitlines() if x.startswith("demo merges"))
    assert "50 % under the inlet, 50 % in the top tenth of the height, 50 % in the bottom tenth" in line
    assert "over 10-25 s: 13.33 per s" in line
    # the window holds the stored 13 and 25 s snapshots: the efficiency line is band_efficiency's over that window
    from analysis import load_run
    from analysis.evidence import band_efficiency
    e = band_efficiency(load_run(root / "demo"), (10.0, 25.0))
    line = next(x for x in report(root).splitlines() if x.startswith("demo collision efficiency where it merges"))
    assert f"E = {e['efficiency']:.3f} +- {e['standard_error']:.3f} in 5 mm cells over 2 snapshot(s)" in line


def test_efficiency_command_prints_a_row_per_run_and_refuses_a_run_without_the_table(tmp_path, capsys):
    import shutil

    from analysis.evidence import main
    from settler.output import MERGES_BY_HEIGHT, PROFILE_BANDS, write_table

    shutil.copytree("data/reference/demo", tmp_path / "demo")
    z = (np.arange(PROFILE_BANDS) + 0.5) * 0.01
    rows = [{"time": t, "z": zk, "merges_under_inlet": n, "merges_elsewhere": 0.0}
            for t, n in ((10.0, 0.0), (25.0, 10.0)) for zk in z]
    write_table(rows, MERGES_BY_HEIGHT, tmp_path / "demo" / "merges_by_height.csv")
    assert main(["--efficiency", str(tmp_path / "demo"), "--cell", "0.01"]) == 0
    row = capsys.readouterr().out.splitlines()[1].split()
    assert row[0] == "demo" and row[2] == "2" and row[3] == "10" and "held" in row
    bare = tmp_path / "bare"  # a stored run without the merge table nor the collision table made from it
    shutil.copytree("data/reference/demo", bare,
                    ignore=shutil.ignore_patterns("merges_by_height.csv", "collisions_by_height.csv"))
    assert main(["--efficiency", str(bare)]) == 2
    assert "no merges_by_height.csv" in capsys.readouterr().err
