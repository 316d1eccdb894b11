"""The zone diagnostics of the full engine (settler.output.ZONE_PROFILE, ZONES, LIFT_BY_SIZE; fulldem/io/zones.py)
against closed forms: the zero of a field linear in the radius, a layer of known thickness and volume fraction, size
bins counted by hand, droplet volume conserved over the bands, and the slag's net flux through a horizontal plane of
a closed box equal and opposite to the droplets' (mixture continuity)."""

import math

import numpy as np
import pytest

from settler.cases import load_case
from settler.output import LIFT_BY_SIZE, MERGES_BY_HEIGHT, PROFILE_BANDS, ROOF_SHARE, ZONE_PROFILE, ZONES


def test_return_radius_is_the_zero_of_a_field_linear_in_the_radius():
    from fulldem.io.zones import return_radius

    h = 1e-3
    x = (np.arange(61) + 0.5) * h
    axis = (30.5e-3, 30.5e-3)
    r = np.hypot(x[:, None] - axis[0], x[None, :] - axis[1])
    # ring means of r - R0 are (mean r of the ring) - R0, linear between the ring centres: the zero is exact
    for r0 in (7.3e-3, 12.05e-3, 2.2e-3):
        assert return_radius(0.04 * (r - r0), x, x, axis, h) == pytest.approx(r0, rel=1e-12)
        assert return_radius(0.04 * (r - r0), x, x, axis, 2.5 * h) == pytest.approx(r0, rel=1e-12)
    assert math.isnan(return_radius(0.04 * (r + 1e-3), x, x, axis, h))   # upward on the axis: no plume
    assert math.isnan(return_radius(-0.04 * (r + 1e-3), x, x, axis, h))  # downward everywhere: no return in the box


def test_roof_layer_of_a_dense_layer_over_a_dilute_suspension():
    from fulldem.io.zones import roof_layer

    area, slice_height, height = 0.01, 2e-3, 0.2
    depth, volume = [], []
    for k in range(50):  # slices 2 mm high down to 0.1 m: 0.2 in the first six (12 mm), 0.02 below
        fraction = 0.2 if k < 6 else 0.02
        depth += [(k + 0.25) * slice_height, (k + 0.75) * slice_height]
        volume += [0.5 * fraction * area * slice_height] * 2
    thickness, mean, peak = roof_layer(np.array(depth), np.array(volume), slice_height, area, height)
    assert thickness == pytest.approx(12e-3, rel=1e-12)
    assert mean == pytest.approx(0.2, rel=1e-12) and peak == pytest.approx(0.2, rel=1e-12)
    # a slice just above ROOF_SHARE of the peak belongs to the layer, one just below does not
    for share, expected in ((ROOF_SHARE * 1.01, 14e-3), (ROOF_SHARE * 0.99, 12e-3)):
        extra = [(6.5) * slice_height]
        vol = volume[:12] + [(share * 0.2 - 0.02) * area * slice_height] + volume[12:]
        got = roof_layer(np.array(depth[:12] + extra + depth[12:]), np.array(vol), slice_height, area, height)
        assert got[0] == pytest.approx(expected, rel=1e-12)
    assert roof_layer(np.array([0.15]), np.array([1e-9]), slice_height, area, height) == (0.0, pytest.approx(math.nan,
                                                                                                            nan_ok=True), 0.0)


def test_lift_table_counts_by_bin():
    from fulldem.io.zones import lift_table

    edges = np.array([1e-3, 2e-3, 4e-3])
    d = np.array([0.5e-3, 1.5e-3, 1.5e-3, 1.9e-3, 3e-3, 5e-3])
    vz = np.array([0.1, -1.0, 2.0, 4.0, -0.5, 0.0])
    rows = {(r["diameter_low"], r["diameter_high"]): r for r in lift_table(d, vz, edges)}
    assert set(rows) == {(0.0, 1e-3), (1e-3, 2e-3), (2e-3, 4e-3), (4e-3, math.inf)}
    assert [rows[k]["count"] for k in sorted(rows)] == [1, 3, 1, 1]
    assert [rows[k]["rising_count"] for k in sorted(rows)] == [1, 2, 0, 0]
    assert rows[(1e-3, 2e-3)]["rising_velocity"] == pytest.approx(3.0, rel=1e-15)
    assert math.isnan(rows[(2e-3, 4e-3)]["rising_velocity"])


def test_zone_files_of_a_short_settling_run(tmp_path):
    """Droplets settling for 0.1 s without feed: the zone files have their columns and a set of rows per snapshot,
    the bands' droplet volume is all the droplets' volume, and every droplet is in the size table."""
    from fulldem.driver import run_case
    from settler.output import read_table

    out = tmp_path / "run"
    case = load_case("demo", ["fulldem.end_time=0.1", "fulldem.snapshot_interval=0.05", "fulldem.output_interval=0.05",
                              "feed.mass_rate=0", "fulldem.fluid_step=0.002"])
    rng = np.random.default_rng(3)
    n = 400
    lower = np.array([0.01, 0.01, 0.2 * case.geometry.height])
    upper = np.array([case.geometry.width - 0.01, case.geometry.depth - 0.01, 0.9 * case.geometry.height])
    position = lower + (upper - lower) * rng.random((n, 3))
    lines = ["x,y,z,diameter"] + [f"{p[0]:.17g},{p[1]:.17g},{p[2]:.17g},{d:.17g}"
                                  for p, d in zip(position, rng.uniform(0.4e-3, 1.2e-3, n))]
    droplets = tmp_path / "droplets.csv"
    droplets.write_text("\n".join(lines) + "\n")
    run_case(case, out, droplets=droplets, feed=False, progress=False)
    for name, columns in (("zone_profile.csv", ZONE_PROFILE), ("zones.csv", ZONES), ("lift_by_size.csv", LIFT_BY_SIZE),
                          ("merges_by_height.csv", MERGES_BY_HEIGHT)):
        table = read_table(out / name)
        assert list(table.columns) == list(columns)
        assert sorted(table["time"].unique()) == pytest.approx([0.0, 0.05, 0.1])
    profile = read_table(out / "zone_profile.csv")
    channel = read_table(out / "channel_profile.csv")
    assert len(profile) == 3 * PROFILE_BANDS
    area = case.geometry.width * case.geometry.depth
    band = case.geometry.height / PROFILE_BANDS
    assert (profile["volume_fraction"] * area * band).to_numpy() == pytest.approx(channel["droplet_volume"].to_numpy(),
                                                                                  rel=1e-12, abs=1e-18)
    lift = read_table(out / "lift_by_size.csv")
    assert lift.groupby("time")["count"].sum().to_numpy() == pytest.approx([n, n, n])
    from analysis import load_run

    from analysis.figures import render_all

    assert render_all(out, tmp_path / "figures")["zones"] == tmp_path / "figures" / "zones.png"
    run = load_run(out)
    assert set(run.zones) == {"zone_profile", "zones", "lift_by_size", "merges_by_height"}
    assert run.zones["zones"]["roof_thickness"].to_numpy() == pytest.approx(read_table(out / "zones.csv")
                                                                            ["roof_thickness"].to_numpy())


def test_slag_flux_through_a_plane_balances_the_droplets_in_a_closed_box():
    """A closed box (no feed, no outlet, no slag inflow): the mixture is incompressible and cannot leave, so at every
    band centre the slag's net volume flux up - down through the plane balances the droplets' volume flux through the
    same faces (sum of q h^2, q the deposited droplet flux). The solve imposes it for the droplets' positions at the
    start of the step; they then move by v dt (tens of micrometres against 5 mm cells), hence the 2 % tolerance on
    the droplets' flux."""
    from fulldem.droplets import DropletStore
    from fulldem.io.zones import snapshot_tables
    from fulldem.stepper import Simulation

    case = load_case("demo", ["feed.mass_rate=0", "fulldem.fluid_step=0.002"])
    rng = np.random.default_rng(5)
    x0, y0 = case.inlet_center
    side = np.arange(-10, 11) * 2.5e-3  # a column of droplets 2.5 mm apart around the inlet axis, jittered
    heights = np.arange(0.3, 0.9, 2.5e-3 / case.geometry.height) * case.geometry.height
    gx, gy, gz = np.meshgrid(x0 + side, y0 + side, heights, indexing="ij")
    position = np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()]) + rng.uniform(-3e-4, 3e-4, (gx.size, 3))
    n = len(position)
    store = DropletStore(2 * n)
    store.add(position, rng.uniform(0.5e-3, 1.0e-3, n), case.matte.density)
    sim = Simulation(case, droplets=store, feed=False)
    for _ in range(60):
        sim.step()
    faces, _ = sim.void_fraction()
    rows = snapshot_tables(sim, faces)["zone_profile.csv"]
    q = sim.particle_flux()[2]
    h = sim.grid.spacing
    checked = 0
    for row in rows:
        k = int(round(row["z"] / h))
        droplets = float(q[:, :, k].sum()) * h * h
        if abs(droplets) < 1e-9:
            continue
        checked += 1
        slag = row["upward_slag_flux"] - row["downward_slag_flux"]
        assert slag == pytest.approx(-droplets, rel=0.02)
        assert row["downward_slag_flux"] > 0.0 and row["upward_slag_flux"] > 0.0
    assert checked >= 4


def test_merge_places_bands_and_the_inlet_region():
    """merge_places: the band of a height (clipped to the slag) and whether (x, y) lies in the inlet's disk or slot,
    by hand."""
    from fulldem.boundaries import Inlet
    from fulldem.stepper import merge_places

    lower, height = np.zeros(3), 0.1
    disk = Inlet((0.05, 0.05), 0.0125, 0.1)
    points = np.array([[0.05, 0.05, 0.0], [0.06, 0.05, 0.0149], [0.0626, 0.05, 0.015], [0.05, 0.05, 0.0999],
                       [0.0, 0.0, 0.12], [0.05, 0.05, -0.001]])
    band, place = merge_places(points, lower, height, disk)
    assert band.tolist() == [0, 1, 1, PROFILE_BANDS - 1, PROFILE_BANDS - 1, 0]
    assert place.tolist() == [0, 0, 1, 0, 1, 0]
    slot = Inlet((0.2, 0.025), 0.0125, 0.1, length=0.375)
    _, place = merge_places(np.array([[0.38, 0.03, 0.05], [0.39, 0.03, 0.05], [0.2, 0.038, 0.05]]), lower, height,
                            slot)
    assert place.tolist() == [0, 1, 1]


def test_merges_by_height_count_every_merge_once_where_it_happened(tmp_path):
    """Two clusters of 150 touching 1 mm droplets, one under the inlet at 44-50 mm and one in a corner at 64-70 mm,
    merging for 1 s (each falls less than 4 mm): the table's last snapshot holds as many merges as the run counted
    (time series), all of them in the clusters' bands (40-50 and 60-70 mm) and places, and its counts never fall."""
    from fulldem.driver import run_case
    from settler.output import MERGES_BY_HEIGHT, read_table

    out = tmp_path / "run"
    case = load_case("demo", ["fulldem.end_time=1.0", "fulldem.snapshot_interval=0.25", "fulldem.output_interval=0.25",
                              "feed.mass_rate=0", "fulldem.fluid_step=0.002"])
    x0, y0 = case.geometry.width / 2, case.geometry.depth / 2
    grid = np.meshgrid(np.arange(5), np.arange(5), np.arange(6), indexing="ij")
    lattice = (np.stack(grid, -1).reshape(-1, 3) - 2.5) * 0.98e-3
    rows = ["x,y,z,diameter"]
    for centre in ((x0, y0, 0.047), (0.012, 0.012, 0.067)):
        for p in np.array(centre) + lattice:
            rows.append(f"{p[0]:.17g},{p[1]:.17g},{p[2]:.17g},1e-3")
    droplets = tmp_path / "droplets.csv"
    droplets.write_text("\n".join(rows) + "\n")
    run_case(case, out, droplets=droplets, feed=False, progress=False)
    table = read_table(out / "merges_by_height.csv")
    assert list(table.columns) == list(MERGES_BY_HEIGHT)
    last = table[table["time"] == table["time"].max()]
    merges = int(read_table(out / "timeseries.csv")["merges"].sum())
    assert merges > 20
    assert int(last["merges_under_inlet"].sum() + last["merges_elsewhere"].sum()) == merges
    under = last.set_index("z")["merges_under_inlet"]
    elsewhere = last.set_index("z")["merges_elsewhere"]
    assert under[under > 0].index.to_numpy() == pytest.approx([0.045])
    assert elsewhere[elsewhere > 0].index.to_numpy() == pytest.approx([0.065])
    for column in ("merges_under_inlet", "merges_elsewhere"):
        assert (table.pivot(index="time", columns="z", values=column).diff().dropna() >= 0).all().all()
