"""The shared time-series schema and atomic writes."""

import json

import numpy as np
import pytest

from settler.cases import load_case
from settler.output import (TIME_SERIES, mass_balance_error, read_time_series, time_series_frame,
                            write_run_metadata, write_time_series)


def test_frame_has_every_column_in_order_and_refuses_unknown():
    frame = time_series_frame([{"time": 0.0, "droplet_count": 3}, {"time": 1.0, "droplet_count": 5}])
    assert list(frame.columns) == list(TIME_SERIES)
    assert np.isnan(frame["max_cfl"]).all()
    with pytest.raises(ValueError, match="droplet_cuont"):
        time_series_frame([{"time": 0.0, "droplet_cuont": 1}])


def test_roundtrip_and_metadata(tmp_path):
    frame = time_series_frame({"time": np.linspace(0, 1, 5), "mass_fed": np.arange(5.0)})
    write_time_series(frame, tmp_path / "timeseries.csv")
    back = read_time_series(tmp_path / "timeseries.csv")
    np.testing.assert_array_equal(back["mass_fed"], frame["mass_fed"])
    assert (tmp_path / "timeseries.csv").read_text().startswith("# units: time [s]")
    write_run_metadata(tmp_path, load_case("simple"), "test", wall_time=1.0)
    meta = json.loads((tmp_path / "metadata.json").read_text())
    assert meta["time_series_units"]["mass_fed"] == "kg"
    assert load_case(tmp_path / "case.toml").to_dict() == load_case("simple").to_dict()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary files left


def test_mass_balance_error():
    assert mass_balance_error(1.0, 0.5, 0.25, 0.125, 0.125) == 0.0
    assert mass_balance_error(0.0, 0.0, 0.0, 0.0, 0.0) == 0.0
