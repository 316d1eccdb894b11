"""Runs: outputs, resume after a kill losing nothing, droplet-list starts, and a clear stop on blow-up."""

import json

import numpy as np
import pandas as pd
import pytest

from fulldem.driver import RunError, run_case
from settler.cases import load_case
from settler.output import TIME_SERIES, read_time_series


SMALL = ["fulldem.cell_size=0.01", "fulldem.output_interval=0.02", "fulldem.snapshot_interval=0.05",
         "fulldem.checkpoint_interval=1000"]


def test_run_writes_every_output(tmp_path):
    case = load_case("demo", SMALL)
    frame = run_case(case, tmp_path, end_time=0.1, progress=False, log=lambda *a: None)
    assert list(frame.columns) == list(TIME_SERIES)
    assert frame["time"].iloc[-1] == pytest.approx(0.1)
    assert frame["mass_fed"].iloc[-1] > 0 and (np.abs(frame["mass_balance_error"]) < 1e-12).all()
    for name in ("case.toml", "metadata.json", "timeseries.csv", "snapshots.pvd", "checkpoint.npz",
                 "droplets_00000.vtu", "fluid_00002.vti", "summary.json", "timeseries.png", "droplets.png"):
        assert (tmp_path / name).exists(), name
    meta = json.loads((tmp_path / "metadata.json").read_text())
    assert meta["engine"] == "fulldem" and meta["dem_substeps"] >= 1
    import meshio

    cloud = meshio.read(tmp_path / "droplets_00002.vtu")
    assert len(cloud.points) == frame["droplet_count"].iloc[-1]


def test_resume_continues_exactly(tmp_path):
    """A run stopped at 0.06 s and resumed to 0.1 s ends in the same state as one run straight to 0.1 s."""
    case = load_case("demo", SMALL)
    straight = run_case(case, tmp_path / "a", end_time=0.1, progress=False, log=lambda *a: None)
    run_case(case, tmp_path / "b", end_time=0.06, progress=False, log=lambda *a: None)
    first = read_time_series(tmp_path / "b" / "timeseries.csv")
    resumed = run_case(case, tmp_path / "b", end_time=0.1, resume=True, progress=False, log=lambda *a: None)
    pd.testing.assert_frame_equal(straight.drop(columns="wall_time"), resumed.drop(columns="wall_time"), rtol=1e-9)
    # the wall-clock column goes on from the first part's total: it never decreases across the resume
    assert (np.diff(resumed["wall_time"]) >= 0.0).all() and (straight["wall_time"] >= 0.0).all()
    assert resumed["wall_time"].iloc[-1] > first["wall_time"].iloc[-1]
    a = np.load(tmp_path / "a" / "checkpoint.npz")
    b = np.load(tmp_path / "b" / "checkpoint.npz")
    np.testing.assert_allclose(a["droplet_position"], b["droplet_position"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(a["u"], b["u"], rtol=1e-9, atol=1e-15)


def test_resume_without_checkpoint_is_refused(tmp_path):
    with pytest.raises(RunError, match="no checkpoint"):
        run_case(load_case("demo", SMALL), tmp_path, end_time=0.01, resume=True, progress=False,
                 log=lambda *a: None)


def test_start_from_droplet_list(tmp_path):
    csv = tmp_path / "drops.csv"
    csv.write_text("x,y,z,diameter,density\n0.05,0.05,0.05,0.001,5000\n0.03,0.05,0.05,0.0015,5100\n")
    case = load_case("demo", SMALL)
    frame = run_case(case, tmp_path / "out", end_time=0.04, droplets=csv, feed=False, progress=False,
                     log=lambda *a: None)
    assert (frame["droplet_count"] == 2).all()
    assert frame["mass_fed"].iloc[0] == pytest.approx(np.pi / 6 * (5000 * 1e-9 + 5100 * 1.5e-3**3), rel=1e-12)
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y,diameter\n0.1,0.1,0.001\n")
    with pytest.raises(RunError, match="missing required column\\(s\\) z"):
        run_case(case, tmp_path / "out2", end_time=0.01, droplets=bad, feed=False, progress=False,
                 log=lambda *a: None)


def test_blow_up_stops_with_last_good_state(tmp_path):
    """Two droplets placed almost on top of each other overlap far beyond fulldem.overlap_abort: the run stops with
    a message naming the cause and saves the last good state."""
    csv = tmp_path / "drops.csv"
    csv.write_text("x,y,z,diameter\n0.05,0.05,0.05,0.001\n0.05,0.05,0.0502,0.001\n")
    case = load_case("demo", SMALL + ["fulldem.overlap_abort=0.5"])
    with pytest.raises(RunError, match="runaway overlap.*last_good.npz") as failure:
        run_case(case, tmp_path, end_time=0.1, droplets=csv, feed=False, progress=False, log=lambda *a: None)
    # the message says when the overlap arose and names the pair: the two placed 0.2 mm apart overlap by 0.8 d
    message = str(failure.value)
    assert "already at the step's start" in message
    assert "deepest pair at the step's start: 0.800 of a diameter, droplet 0 (diameter 1 mm, contact 1 mm, free" \
        in message and "droplet 1 (" in message
    assert (tmp_path / "last_good.npz").exists()
    assert read_time_series(tmp_path / "timeseries.csv")["time"].iloc[0] == 0.0


def test_progress_eta_extrapolates_from_the_first_report(monkeypatch):
    """The ETA uses the pace after the first report (whose step includes compilation): 1 s of simulated time in
    the first 30 s of wall (compiling), then 1 s per 2 s of wall, 10 s to go: ETA 20 s, not 10 x 32/2 s."""
    import io
    import types

    from fulldem.io import progress as fio

    clock = iter([0.0, 30.0, 32.0])
    monkeypatch.setattr(fio, "_time", types.SimpleNamespace(perf_counter=lambda: next(clock)))
    stream = io.StringIO()
    bar = fio.Progress(0.0, 12.0, stream=stream)
    bar.update(1.0, 10, force=True)
    bar.update(2.0, 10, force=True)
    first, second = stream.getvalue().splitlines()
    assert "ETA     nan s" in first
    assert "ETA    20.0 s" in second


def test_the_deepest_pair_skips_coalescence_partners():
    """deepest_pair names the most overlapping pair by the smaller contact diameter, exactly, and passes over a
    marked pair (partners exert no contact force on each other, so their overlap is no failure)."""
    import numpy as np

    from fulldem.dem.diagnostics import deepest_pair

    x = np.array([[0.0, 0.0, 0.0], [0.2e-3, 0.0, 0.0], [0.0, 0.0, 0.9e-3], [5e-3, 0.0, 0.0]])
    d = np.array([1.0e-3, 1.0e-3, 0.5e-3, 1.0e-3])  # 0-1 overlap by 0.8 mm, 0-2 by 0.75 - 0.9 = -0.15 mm: apart
    partner = np.array([1, 0, -1, -1])
    assert deepest_pair(x, d, partner, 4) == (-1, -1, 0.0)  # only the partners touch
    d[2] = 1.0e-3  # 0-2 now overlap by 1.0 - 0.9 = 0.1 mm: 0.1 of the smaller diameter
    i, j, ratio = deepest_pair(x, d, partner, 4)
    assert {i, j} == {0, 2} and ratio == pytest.approx(0.1, rel=1e-9)
    partner[:] = -1  # unmarked, 0-1 is the deepest: 0.8 of a diameter
    assert deepest_pair(x, d, partner, 4)[2] == pytest.approx(0.8, rel=1e-9)
