"""analysis.runs.load_run on a short popbal run made here, on the stored deep reference (a real full run) and on a
synthetic full-run folder with .vtu snapshots: what it reads equals what was written, the distribution's labelled
dims carry the droplet count of the time series (a conservation check), netCDF round trips exactly with units, and
a folder that is not a run is refused in one line."""

import json
import re

import numpy as np
import pytest
import xarray as xr

import popbal
from popbal.driver import EXCHANGES
from analysis import Run, load_run
from analysis.figures import NoData
from analysis.runs import array_dims, read_netcdf, write_netcdf
from settler.output import TIME_SERIES, OutputError
from test_analysis_figures import N_DROPLETS, TIMES, _make_run  # the synthetic full run of the figures' tests

REFERENCE = "data/reference/deep"


@pytest.fixture(scope="module")
def reduced(tmp_path_factory):
    """(folder, Result) of a short, coarse popbal run of the simple case (about a second)."""
    model = popbal.setup("simple", {"popbal.height_cells": 10, "popbal.sections_per_doubling": 1})
    result = popbal.run(model, end_time=4.0, output_interval=0.5, progress=False)
    return result.save(tmp_path_factory.mktemp("runs") / "simple"), result


def test_popbal_run_is_read_back(reduced):
    folder, result = reduced
    run = load_run(folder)
    assert isinstance(run, Run) and run.engine == "popbal" and not run.is_reference
    assert run.name == "simple" and run.case.geometry.height == result.case.geometry.height
    np.testing.assert_array_equal(run.timeseries.to_numpy(), result.timeseries.to_numpy())
    assert run.units == {c: u for c, (u, _) in TIME_SERIES.items()}
    assert run.metadata["engine"] == "popbal" and run.merges_by_size is None
    assert len(run.channel_profile) == len(result.channel_profile)
    assert load_run(run) is run
    with pytest.raises(NoData, match="popbal run has no droplet"):
        run.droplets()


def test_distribution_dataset_labels_and_units(reduced):
    folder, result = reduced
    ds = load_run(folder).distribution()
    model = result.model
    assert dict(ds.sizes) == {"time": 9, "zone": len(popbal.ZONES), "z": model.cells, "section": model.grid.size,
                              "path": len(EXCHANGES)}
    assert ds.number_density.dims == ("time", "zone", "z", "section") and ds.fed_mass.dims == ("time", "section")
    assert list(ds.zone.values) == list(popbal.ZONES) and list(ds.path.values) == list(EXCHANGES)
    assert ds.exchanges.dims == ("time", "path")
    for name, (unit, _) in popbal.DISTRIBUTION_ARRAYS.items():
        assert ds[name].attrs["units"] == unit
        np.testing.assert_array_equal(ds[name].values, result.arrays[name])
    # conservation: droplets per m^3 x zone area x cell height, summed, is the time series' droplet count
    cell_height = float(np.diff(ds.z.values).mean())
    count = (ds.number_density * ds.zone_area * cell_height).sum(("zone", "z", "section"))
    np.testing.assert_allclose(count.values, result.timeseries["droplet_count"].to_numpy(), rtol=1e-12)
    # the fed mass by section adds up to the time series' mass fed
    np.testing.assert_allclose(ds.fed_mass.sum("section").values, result.timeseries["mass_fed"].to_numpy(),
                               rtol=1e-12)


def test_netcdf_round_trip_is_exact_and_compressed(reduced, tmp_path):
    folder, _ = reduced
    run = load_run(folder)
    path = run.to_netcdf(tmp_path / "distribution.nc")
    back = read_netcdf(path)
    xr.testing.assert_equal(back, run.distribution())  # values (NaN included), coords and dims
    # attributes as written, in CF-1.10 (analysis.cf): UDUNITS units, axis attributes, the conventions named
    assert back.number_density.attrs["units"] == "m-3" and back.time.attrs["units"] == "s"
    assert back.time.attrs["axis"] == "T" and back.attrs["Conventions"] == "CF-1.10"
    assert back.time.dtype == np.float64  # seconds stay seconds (no timedelta decoding)
    assert back.number_density.encoding["zlib"] and back.number_density.encoding["complevel"] == 4
    series = read_netcdf(run.to_netcdf(tmp_path / "timeseries.nc", part="timeseries"))
    xr.testing.assert_equal(series, run.timeseries_dataset())
    assert series.mass_fed.attrs == {"units": "kg", "long_name": TIME_SERIES["mass_fed"][1]}
    assert "[case]" in series.attrs["settler_case"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["distribution.nc", "timeseries.nc"]  # no temporaries
    with pytest.raises(ValueError, match="part = 'x'"):
        run.to_netcdf(tmp_path / "x.nc", part="x")


def test_stored_reference_is_read(tmp_path):
    run = load_run(REFERENCE)
    info = json.loads(open(f"{REFERENCE}/reference.json").read())
    assert run.engine == "fulldem" and run.is_reference and run.name == "deep"
    assert run.metadata == info["metadata"]  # a reference keeps metadata.json inside reference.json
    np.testing.assert_array_equal(run.snapshot_times(), info["snapshots"]["times"])
    times = info["snapshots"]["times"]
    t, droplets = run.droplets(times[0] + 0.4)  # the snapshot nearest the time asked for
    assert t == times[0] and len(droplets) == info["snapshots"]["droplets"][0]
    assert {"x", "z", "diameter", "settling_velocity", "merged"} <= set(droplets.columns)
    t, centres, velocity = run.slag()
    assert t == times[-1] and centres.shape == velocity.shape and centres.shape[1] == 3
    assert run.merges_by_size["merges"].sum() > 0 and set(run.channel_profile.columns) >= {"z", "channel_radius"}
    ds = run.timeseries_dataset()
    np.testing.assert_array_equal(ds.droplet_count.values, run.timeseries["droplet_count"].to_numpy())
    assert ds.time.attrs["units"] == "s" and ds.channel_velocity.attrs["units"] == "m/s"
    with pytest.raises(OutputError, match="only a popbal run"):
        run.distribution()


def test_full_run_folder_snapshots_on_demand(tmp_path):
    folder = tmp_path / "full"
    written = _make_run(folder)  # no metadata.json: the engine is told by snapshots.pvd
    run = load_run(folder)
    assert run.engine == "fulldem" and not run.is_reference and run.metadata is None
    np.testing.assert_array_equal(run.snapshot_times(), TIMES)
    t, frame = run.droplets(TIMES[0])
    points, data = written[TIMES[0]]
    assert t == TIMES[0] and len(frame) == N_DROPLETS
    np.testing.assert_array_equal(frame[["x", "y", "z"]].to_numpy(), points)
    np.testing.assert_array_equal(frame["diameter"].to_numpy(), data["diameter"])


def test_units_come_from_the_csv_line(tmp_path):
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "timeseries.csv").write_text("# units: time [s], droplet_count [-], extra [kg/m^3]\n"
                                           "time,droplet_count,extra\n0,1,2\n1,3,4\n")
    run = load_run(folder)
    assert run.engine is None and run.units["extra"] == "kg/m^3"
    ds = run.timeseries_dataset()
    assert ds.extra.attrs == {"units": "kg/m^3"} and list(ds.extra.values) == [2.0, 4.0]
    with pytest.raises(OutputError, match="case.toml: missing"):
        run.case


def _not_a_run(base, kind):
    """A folder of the given kind that is not a run (or a file, or nothing)."""
    folder = base / kind
    if kind == "file":
        folder.write_text("x")
    elif kind != "missing":
        folder.mkdir()
    if kind == "no_time":
        (folder / "timeseries.csv").write_text("a,b\n1,2\n")
    if kind == "bad_json":
        (folder / "timeseries.csv").write_text("time\n0\n")
        (folder / "metadata.json").write_text("{")
    return folder


@pytest.mark.parametrize("kind, message", [
    ("missing", "no such run folder"), ("file", "is a file, not a run folder"),
    ("empty", "not a run folder (no timeseries.csv)"), ("no_time", "has no time column"),
    ("bad_json", "cannot be read as JSON")])
def test_not_a_run_is_refused_in_one_line(tmp_path, kind, message):
    folder = _not_a_run(tmp_path, kind)
    with pytest.raises(OutputError, match=re.escape(message)) as info:
        load_run(folder)
    assert str(folder) in str(info.value) and "\n" not in str(info.value)


def test_distribution_shapes_are_checked():
    with pytest.raises(OutputError, match="shape note"):
        array_dims("x", "droplets per m^3")
    from analysis.runs import distribution_dataset

    with pytest.raises(OutputError, match="time has 3 entries"):
        distribution_dataset({"time": np.zeros(2), "fed_mass": np.zeros((3, 4))},
                             {"time": ("s", "(T,) t"), "fed_mass": ("kg", "(T, K) m")})


def test_write_netcdf_leaves_the_old_file_on_failure(tmp_path):
    path = tmp_path / "a.nc"
    good = xr.Dataset({"v": ("time", np.arange(3.0), {"units": "m"})})
    write_netcdf(good, path)
    bad = xr.Dataset({"v": ("time", np.arange(3.0))}, attrs={"unsupported": {"a": 1}})  # dict attrs cannot be written
    with pytest.raises((TypeError, ValueError)):
        write_netcdf(bad, path)
    xr.testing.assert_equal(read_netcdf(path), good)
    assert read_netcdf(path).attrs["Conventions"] == "CF-1.10"
    assert [p.name for p in tmp_path.iterdir()] == ["a.nc"]
