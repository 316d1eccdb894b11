"""analysis.floor_lift: what the return flow lifts off the floor, by size, counted droplet by droplet between
snapshots, and the fit of popbal's form lambda exp(-(U / u_b)^2) to the counts (the measure behind
popbal.bottom_lift_share)."""

import json
import math

import meshio
import numpy as np
import pandas as pd
import pytest

from analysis.floor_lift import (EDGES, FLOOR_BAND, fit_lift, lift_counts, measure_floor_lift, read_floor_lift,
                                 write_floor_lift)
from popbal.closures import lift_share
from settler.cases import load_case
from settler.derived import settling_velocity
from settler.output import time_series_frame, write_time_series

HEIGHT = 0.1  # the demo's slag height [m]


def _frame(ident, z, diameter):
    return pd.DataFrame({"ident": np.asarray(ident, dtype=float), "z": np.asarray(z, dtype=float),
                         "diameter": np.asarray(diameter, dtype=float)})


def test_counts_follow_each_floor_droplet_to_the_next_snapshot():
    """Five floor droplets of 0.45 mm and three of 0.9 mm at t = 0; at t = 2 s two small ones are above the band
    (lifted), one small and two large are gone (settled or merged), the rest still on the floor; a droplet above the
    band at t = 0 and a new one at t = 2 count for nothing."""
    band = FLOOR_BAND * HEIGHT
    first = _frame([1, 2, 3, 4, 5, 6, 7, 8, 9], [0.002] * 8 + [0.05], [4.5e-4] * 5 + [9e-4] * 3 + [4.5e-4])
    second = _frame([1, 2, 3, 4, 8, 9, 10], [0.5 * band, 1.5 * band, 3 * band, 0.001, 0.003, 0.04, 0.001],
                    [4.5e-4] * 4 + [9e-4, 4.5e-4, 6e-4])
    table, span = lift_counts([(0.0, first), (2.0, second)], HEIGHT)
    assert span == 2.0
    small = table[(table.diameter_low == 4e-4)].iloc[0]
    large = table[(table.diameter_low == 8e-4)].iloc[0]
    assert (small.held, small.lifted, small.left) == (5, 1.0, 0.5)  # ids 2, 3 lifted; 5 gone; over 2 s
    assert (large.held, large.lifted, large.left) == (3, 0.0, 1.0)  # ids 6, 7 gone
    assert small.share == pytest.approx(2.0 / 3.0) and large.share == 0.0
    assert small.mean_diameter == pytest.approx(4.5e-4)
    assert table["held"].sum() == 8
    with pytest.raises(ValueError, match="two or more"):
        lift_counts([(0.0, first)], HEIGHT)
    with pytest.raises(ValueError, match="no ident"):
        lift_counts([(0.0, first.drop(columns="ident")), (1.0, second)], HEIGHT)


def test_the_fit_recovers_the_share_and_velocity_that_made_the_counts():
    """Counts drawn from lambda = 0.15, u_b = 0.8 mm/s with many droplets per bin: the binomial fit returns them
    within a few standard errors, and the standard errors shrink as one over the square root of the counts."""
    rng = np.random.default_rng(7)
    u = np.array([0.2, 0.4, 0.6, 0.8, 1.0, 1.3, 1.8, 2.5]) * 1e-3
    p = lift_share(u, 0.15, 0.8e-3)
    for n, tolerance in ((20_000, 4.0), (200_000, 4.0)):
        lifted = rng.binomial(n, p)
        fit = fit_lift(u, lifted, n - lifted)
        se = fit["standard_errors"]
        assert fit["converged"]
        assert abs(fit["share"] - 0.15) < tolerance * se[0] and abs(fit["lift_velocity"] - 0.8e-3) < tolerance * se[1]
        assert se[0] < 0.01 * math.sqrt(20_000 / n) and se[1] < 0.03e-3 * math.sqrt(20_000 / n)
    nothing = fit_lift(u, np.zeros(len(u)), np.full(len(u), 100.0))
    assert math.isnan(nothing["share"]) and not nothing["converged"]


def _run_folder(folder, snapshots):
    """A synthetic full-run folder of the demo case holding ``snapshots`` [(time, points, point_data)]."""
    folder.mkdir()
    (folder / "case.toml").write_text(load_case("demo").to_toml())
    (folder / "metadata.json").write_text(json.dumps({"engine": "fulldem", "command": "settler full demo --out X"}))
    times = [t for t, _, _ in snapshots]
    rows = [{"time": t, "droplet_count": 100.0, "mass_fed": 1e-3 * t} for t in np.linspace(0.0, times[-1], 31)]
    write_time_series(time_series_frame(rows), folder / "timeseries.csv")
    entries = []
    for index, (time, points, data) in enumerate(snapshots):
        mesh = meshio.Mesh(points, [("vertex", np.arange(len(points)).reshape(-1, 1))], point_data=data)
        meshio.write(folder / f"droplets_{index:05d}.vtu", mesh, file_format="vtu", binary=True)
        entries.append(f'    <DataSet timestep="{time:.9g}" part="0" file="droplets_{index:05d}.vtu"/>')
    (folder / "snapshots.pvd").write_text('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n'
                                          "  <Collection>\n" + "\n".join(entries) + "\n  </Collection>\n</VTKFile>\n")


def test_a_run_folders_floor_lift_is_measured_stored_and_read_back(tmp_path):
    """Three snapshots 1 s apart, 400 floor droplets of 0.45 mm and 400 of 1.1 mm each time, fresh idents each
    snapshot: a tenth of the small ones (the same idents) turn up above the band a second later, every other floor
    droplet is gone. The table gives the small bin's share 0.1 and the large one's 0, their own settling velocities,
    and the file round-trips; a stored reference's single plane gives no upflow (NaN)."""
    rng = np.random.default_rng(3)
    snapshots, next_ident, lifted_ids = [], 0, np.array([], dtype=int)
    for time in (20.0, 21.0, 22.0):
        n = 800
        ident = np.arange(next_ident, next_ident + n)
        next_ident += n
        diameter = np.where(np.arange(n) < 400, 4.5e-4, 1.1e-3)
        points = np.column_stack([rng.uniform(0.01, 0.09, n), rng.uniform(0.01, 0.09, n),
                                  rng.uniform(0.0, 0.009, n)])
        if lifted_ids.size:  # last snapshot's lifted droplets, now above the band
            ident = np.concatenate([ident, lifted_ids])
            diameter = np.concatenate([diameter, np.full(lifted_ids.size, 4.5e-4)])
            points = np.vstack([points, np.column_stack([np.full((lifted_ids.size, 2), 0.08),
                                                         np.full(lifted_ids.size, 0.03)])])
        lifted_ids = ident[:40]  # a tenth of this snapshot's small floor droplets
        count = len(ident)
        data = {"diameter": diameter, "velocity": np.zeros((count, 3)), "density": np.full(count, 5100.0),
                "age": np.zeros(count), "ident": ident.astype(float), "merged": np.zeros(count)}
        snapshots.append((time, points, data))
    folder = tmp_path / "run"
    _run_folder(folder, snapshots)
    table, meta = measure_floor_lift(folder, (20.0, 22.0))
    small = table[table.diameter_low == 4e-4].iloc[0]
    large = table[table.diameter_low == 1e-3].iloc[0]
    assert small.share == pytest.approx(0.1) and small.lifted == pytest.approx(40.0)
    assert large.share == 0.0 and large.left == pytest.approx(400.0)
    case = load_case("demo")
    assert small.settling_velocity == pytest.approx(float(settling_velocity(case, 4.5e-4)), rel=1e-6)
    assert meta["snapshots"] == [20.0, 21.0, 22.0] and math.isnan(meta["upflow"])
    path = write_floor_lift(folder, tmp_path, (20.0, 22.0))
    again, read = read_floor_lift(path)
    assert again["share"].to_numpy() == pytest.approx(table["share"].to_numpy(), nan_ok=True)
    assert read["share"] == pytest.approx(meta["share"]) and read["window"] == (20.0, 22.0)
    assert len(EDGES) - 1 == len(again)
