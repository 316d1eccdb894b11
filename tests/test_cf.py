"""The netCDF files the toolkit writes follow CF-1.10 (issue: files that load in one call): units in UDUNITS-2
spelling, Conventions, axis attributes on time and height, the resolved case embedded; ``xarray.open_dataset``
reads them with no options and selects output times by value."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from analysis import load_run
from analysis.cf import CONVENTIONS, apply, udunits
from analysis.runs import write_netcdf
from analysis.sweep.execution import write_dataset

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("ours, spelled", [
    ("-", "1"), ("", "1"), ("m", "m"), ("kg/m^3", "kg m-3"), ("m^3/s", "m3 s-1"), ("1/s", "s-1"),
    ("Pa s", "Pa s"), ("m/s", "m s-1"), ("J/mol", "J mol-1"), ("1/m^3", "m-3"), ("m^2", "m2"), ("kg/s", "kg s-1"),
])
def test_units_in_udunits_spelling(ours, spelled):
    assert udunits(ours) == spelled


@pytest.mark.parametrize("text", ["unknown", "a/b/c", "droplets per cell", "m/"])
def test_a_unit_that_cannot_be_spelled_is_left_out_not_guessed(text):
    assert udunits(text) is None


def _check_cf(dataset, case_expected=True):
    assert dataset.attrs["Conventions"] == CONVENTIONS
    assert dataset.attrs["title"] and dataset.attrs["history"] and dataset.attrs["source"].startswith("settler")
    if case_expected:
        assert "[case]" in dataset.attrs["settler_case"]
    for name, variable in dataset.variables.items():
        if variable.dtype.kind in "fiu" and "units" in variable.attrs:
            assert udunits(variable.attrs["units"]) == variable.attrs["units"], (name, variable.attrs["units"])


def test_a_stored_run_written_as_netcdf_is_cf_and_selects_output_times(tmp_path):
    run = load_run(ROOT / "data" / "reference" / "simple")
    path = run.to_netcdf(tmp_path / "simple.nc", part="timeseries")
    with xr.open_dataset(path) as dataset:
        _check_cf(dataset)
        assert dataset["time"].attrs["axis"] == "T" and dataset["time"].attrs["units"] == "s"
        assert dataset["droplet_count"].attrs["units"] == "1"
        # an output time of the run, selected by its value (times are rounded to the output interval's decimals)
        row = run.timeseries[run.timeseries["time"] == 30.0]
        assert len(row) == 1
        assert float(dataset.sel(time=30.0)["droplet_count"]) == float(row["droplet_count"].iloc[0])


def test_every_writer_applies_the_conventions(tmp_path):
    """The sweeps' writer (write_dataset) and the runs' (write_netcdf) both go through analysis.cf.apply."""
    dataset = xr.Dataset({"loss": ("point", np.array([0.1, 0.2]), {"units": "-"}),
                          "height": ("z", np.array([1.0, 2.0]), {"units": "m"})},
                         coords={"z": ("z", np.array([0.5, 1.5]), {"units": "m"})},
                         attrs={"case": "demo", "settler_case": "[case]\nname = \"demo\"\n"})
    for writer, path in ((write_dataset, tmp_path / "sweep.nc"), (write_netcdf, tmp_path / "run.nc")):
        writer(dataset, path)
        with xr.open_dataset(path) as back:
            _check_cf(back)
            assert back["loss"].attrs["units"] == "1"
            assert back["z"].attrs == {"units": "m", "axis": "Z", "standard_name": "height", "positive": "up"}
    assert dataset.attrs.get("Conventions") is None  # the caller's dataset is left as it was
    assert dataset["loss"].attrs == {"units": "-"} and "axis" not in dataset["z"].attrs


def test_apply_leaves_strings_without_units():
    dataset = apply(xr.Dataset({"status": ("point", np.array(["done", "failed"]), {"units": "-"})}), title="t")
    assert "units" not in dataset["status"].attrs
