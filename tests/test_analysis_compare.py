"""analysis.compare: the error definition on hand-made series with known answers, the side-by-side table, windows,
skipped columns, and ``settler compare`` on the stored deep reference against a short popbal run."""

import json
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.compare import (COLUMNS, Window, compare, default_windows, interpolate, parse_windows,
                              relative_error, side_by_side, window_errors)
from settler.cli import main
from settler.output import OutputError, read_time_series, time_series_frame, write_run_metadata, write_time_series

REFERENCE = "data/reference/deep"
DESIGNED = "data/calibration/designed.toml"


def _series(time, **columns):
    """A shared-schema time series (settler.output) with the given columns; the rest NaN."""
    return time_series_frame({"time": np.asarray(time, dtype=float), **columns})


def _write_run(folder, frame, engine):
    """A minimal run folder: timeseries.csv and metadata.json naming the engine (case.toml from the deep
    reference)."""
    from settler.cases import load_case

    folder.mkdir(parents=True, exist_ok=True)
    write_time_series(frame, folder / "timeseries.csv")
    write_run_metadata(folder, load_case(f"{REFERENCE}/case.toml"), engine)
    return folder


def _hand_made(time):
    """A full-like series with every compared column varying in time (no zeros, so relative errors exist)."""
    return {"droplet_count": 1000.0 + 50.0 * time, "mean_diameter": 5e-4 + 1e-6 * time,
            "sauter_diameter": 6e-4 + 2e-6 * time, "mass_fed": 1.0 + time, "mass_settled": 0.1 + 0.5 * time,
            "channel_radius": 0.01 + 1e-4 * np.sin(time), "channel_velocity": 0.05 + 1e-3 * time,
            "mean_settling_velocity": 0.002 + 1e-5 * time}


# ------------------------------------------------------------------------------------------ the definition
def test_relative_error_is_the_stated_formula():
    assert relative_error(2.0, 2.2) == pytest.approx(0.1, rel=1e-12)
    assert relative_error(-4.0, -3.0) == pytest.approx(0.25, rel=1e-12)
    assert math.isnan(relative_error(0.0, 1.0))
    assert math.isnan(relative_error(float("nan"), 1.0))


def test_window_errors_by_hand():
    time = np.arange(0.0, 10.5, 0.5)
    full = 1.0 + time
    reduced = full.copy()
    reduced[time > 5.0] *= 1.3
    reduced[3] = np.nan  # t = 1.5: left out of both means
    errors = window_errors(time, full, reduced, [Window("early", 0.0, 5.0), ("late", 5.5, 10.0), ("none", 20, 30)])
    early, late, none = errors.to_dict("records")
    inside = (time <= 5.0) & (time != 1.5)
    assert early["points"] == inside.sum() == 10
    assert early["mean_full"] == pytest.approx(np.mean(full[inside])) and early["relative_error"] == 0.0
    assert late["points"] == 10 and late["relative_error"] == pytest.approx(0.3, rel=1e-12)
    assert none["points"] == 0 and math.isnan(none["relative_error"])


def test_window_errors_refuses_unequal_lengths():
    with pytest.raises(ValueError, match="shape"):
        window_errors([0.0, 1.0], [1.0, 2.0], [1.0], [Window("all", 0.0, 1.0)])


def test_default_windows_are_quarters_and_the_last_third():
    windows = default_windows(0.0, 60.0)
    assert [(w.name, w.start, w.end) for w in windows] == [
        ("q1", 0.0, 15.0), ("q2", 15.0, 30.0), ("q3", 30.0, 45.0), ("q4", 45.0, 60.0), ("steady", 40.0, 60.0)]


def test_parse_windows():
    windows = parse_windows("2:4, late=5:9.5, steady", 0.0, 30.0)
    assert windows == [Window("2-4", 2.0, 4.0), Window("late", 5.0, 9.5), Window("steady", 20.0, 30.0)]
    assert len(parse_windows("default", 0.0, 1.0)) == 5
    for bad, message in (("4:2", "START < END"), ("a:b", "START:END"), ("x", "START:END"), ("1:inf", "finite"),
                         ("a=1:2,a=3:4", "repeated")):
        with pytest.raises(OutputError, match=message):
            parse_windows(bad, 0.0, 10.0)


def test_interpolate_no_extrapolation_and_nan_gaps():
    source_t = np.array([0.0, 1.0, 2.0, 3.0])
    values = np.array([0.0, 10.0, np.nan, 30.0])
    out = interpolate([0.5, 1.0, 1.5, 2.5, 3.0, 3.5, -1.0], source_t, values)
    np.testing.assert_array_equal(out[:2], [5.0, 10.0])
    assert np.isnan(out[2]) and np.isnan(out[3])  # next to the NaN
    assert out[4] == 30.0 and np.isnan(out[5]) and np.isnan(out[6])  # exact end; outside the span


# --------------------------------------------------------------------------------------------- the tables
def test_a_run_against_itself_has_zero_error(tmp_path):
    time = np.linspace(0.0, 12.0, 49)
    frame = _series(time, **_hand_made(time))
    full = _write_run(tmp_path / "full", frame, "fulldem")
    reduced = _write_run(tmp_path / "reduced", frame, "popbal")
    result = compare(full, reduced)
    assert result.skipped == {} and result.compared == list(COLUMNS)
    assert len(result.errors) == len(COLUMNS) * 5
    np.testing.assert_array_equal(result.errors["relative_error"], 0.0)
    for column in COLUMNS:
        np.testing.assert_array_equal(result.table[f"{column}_full"], result.table[f"{column}_reduced"])


def test_scaled_reduced_run_has_ten_percent_error_and_interpolation_is_exact_for_lines(tmp_path):
    full_t = np.linspace(0.0, 12.0, 49)  # every 0.25 s
    reduced_t = np.linspace(0.0, 12.0, 7)  # every 2 s: linear columns interpolate exactly in between
    linear = {c: v for c, v in _hand_made(reduced_t).items() if c != "channel_radius"}
    scaled = {c: 1.1 * v for c, v in linear.items() if c not in ("mass_fed", "mass_settled")}
    scaled.update(mass_fed=linear["mass_fed"], mass_settled=1.1 * linear["mass_settled"])  # settled fraction x 1.1
    full = _write_run(tmp_path / "full", _series(full_t, **{c: v for c, v in _hand_made(full_t).items()
                                                            if c != "channel_radius"}), "fulldem")
    reduced = _write_run(tmp_path / "reduced", _series(reduced_t, **scaled), "popbal")
    result = compare(full, reduced)
    assert set(result.skipped) == {"channel_radius"} and "full and the reduced" in result.skipped["channel_radius"]
    compared = result.errors[result.errors["column"] != "channel_radius"]
    np.testing.assert_allclose(compared["relative_error"], 0.1, rtol=1e-9)
    assert (compared["points"] > 0).all()
    skipped = result.errors[result.errors["column"] == "channel_radius"]
    assert skipped["relative_error"].isna().all() and skipped["note"].str.startswith("skipped: NaN").all()
    # settled fraction by hand at t = 3 s (between reduced outputs at 2 and 4 s)
    row = result.table[result.table["time"] == 3.0].iloc[0]
    assert row["settled_fraction_full"] == pytest.approx((0.1 + 1.5) / 4.0, rel=1e-12)
    assert row["settled_fraction_reduced"] == pytest.approx(1.1 * (0.1 + 1.5) / 4.0, rel=1e-12)


def test_table_covers_the_common_span_only():
    full = _series(np.arange(0.0, 10.01, 1.0), droplet_count=np.arange(11.0))
    reduced = _series(np.arange(2.0, 6.01, 2.0), droplet_count=np.array([2.0, 4.0, 6.0]))
    table = side_by_side(full, reduced)
    np.testing.assert_array_equal(table["time"], [2.0, 3.0, 4.0, 5.0, 6.0])
    np.testing.assert_array_equal(table["droplet_count_reduced"], table["droplet_count_full"])
    with pytest.raises(OutputError, match="share no time span"):
        side_by_side(full, _series([20.0, 30.0], droplet_count=[1.0, 1.0]))


# ------------------------------------------------------------------------------------------- the command
@pytest.fixture(scope="module")
def reduced_deep(tmp_path_factory):
    """A short popbal run of the deep case (coarse settings: about a second)."""
    import popbal

    model = popbal.setup("deep", {"popbal.height_cells": 20, "popbal.sections_per_doubling": 2})
    result = popbal.run(model, end_time=20.0, output_interval=1.0, progress=False)
    return result.save(tmp_path_factory.mktemp("reduced") / "deep")


def test_command_writes_the_comparison(tmp_path, reduced_deep, capsys):
    out = tmp_path / "cmp"
    assert main(["compare", REFERENCE, str(reduced_deep), "--out", str(out), "--windows", "early=0:10,steady"]) == 0
    printed = capsys.readouterr().out
    assert "relative error [%]" in printed and "droplet_count" in printed and "early" in printed
    table = read_time_series(out / "comparison.csv")
    full = read_time_series(f"{REFERENCE}/timeseries.csv")
    expected_times = full["time"][full["time"] <= 20.0 + 1e-9].to_numpy()
    np.testing.assert_allclose(table["time"], expected_times)
    np.testing.assert_allclose(table["droplet_count_full"], full["droplet_count"][:len(expected_times)])
    assert (out / "comparison.csv").read_text().startswith("# units: time [s], droplet_count_full [-]")
    errors = pd.read_csv(out / "errors.csv", comment="#")
    assert set(errors["window"]) == {"early", "steady"} and set(errors["column"]) == set(COLUMNS)
    # one error recomputed by hand from the written table: droplet count over 0-10 s
    rows = table[(table["time"] <= 10.0)]
    both = rows[["droplet_count_full", "droplet_count_reduced"]].dropna()
    by_hand = abs(both.iloc[:, 1].mean() - both.iloc[:, 0].mean()) / abs(both.iloc[:, 0].mean())
    got = errors[(errors["column"] == "droplet_count") & (errors["window"] == "early")]["relative_error"].item()
    assert got == pytest.approx(by_hand, rel=1e-9)
    # nothing reaches the floor of the deep case in the first 10 s: no relative error, and the note says why
    early = errors[(errors["column"] == "settled_fraction") & (errors["window"] == "early")].iloc[0]
    assert early["mean_full"] == 0.0 and np.isnan(early["relative_error"]) and "mean is 0" in early["note"]
    info = json.loads((out / "comparison.json").read_text())
    assert info["full"]["engine"] == "fulldem" and info["reduced"]["engine"] == "popbal"
    assert info["windows"][1] == {"name": "steady", "start": pytest.approx(40.0 / 3.0), "end": 20.0}
    assert (out / "comparison.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_command_refuses_what_is_not_a_run(tmp_path, reduced_deep, capsys):
    (tmp_path / "empty").mkdir()
    for full, what in ((tmp_path / "missing", "no such run folder"), (tmp_path / "empty", "not a run folder")):
        assert main(["compare", str(full), str(reduced_deep), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err.strip()
        assert what in err and len(err.splitlines()) == 1
    assert not (tmp_path / "o").exists()
    assert main(["compare", REFERENCE, str(reduced_deep), "--out", str(tmp_path / "o"), "--windows", "5:1"]) == 2
    assert "--windows '5:1'" in capsys.readouterr().err
    assert main(["compare", REFERENCE, str(reduced_deep), "--out", str(reduced_deep)]) == 2  # a run folder
    assert "holds another run" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------------- the band
def _certain_layer(path, delta=0.0):
    """data/calibration/designed.toml with every standard error and the discrepancies set to 0 (or ``delta``): a
    layer whose band must collapse onto the run at its estimates."""
    import re

    text = (Path(DESIGNED).read_text(encoding="utf-8"))
    text = re.sub(r"^standard_error = [^ ]+", "standard_error = 0.0", text, flags=re.M)
    text = re.sub(r"^discrepancy = [^ ]+", f"discrepancy = {delta!r}", text, flags=re.M)
    text = re.sub(r"^(channel_coefficient|return_flow_ratio|shear_coefficient) = \[([^,]+), [^,]+, ",
                  r"\1 = [\2, 0.0, ", text, flags=re.M)  # [estimate, standard error 0, profile interval]
    path.write_text(text, encoding="utf-8")
    return path


@pytest.fixture
def certain_layer(tmp_path, monkeypatch):
    from settler import cases

    layer = _certain_layer(tmp_path / "certain.toml")
    real = cases.calibration_path
    monkeypatch.setattr(cases, "calibration_path", lambda name: layer if name == "certain" else real(name))
    return "certain"


def test_band_of_a_layer_without_uncertainty_is_the_run_at_its_estimates(tmp_path, reduced_deep, certain_layer):
    """No parameter spread and no discrepancy: every band run is popbal on the reduced run's case with the layer's
    values, so the band's ends equal that run's columns on the full run's times (to round-off), and a full window
    mean lies inside only if it equals the reduced one."""
    import popbal
    from analysis.compare import prediction_band, with_band
    from settler.cases import load_case

    comparison = compare(REFERENCE, reduced_deep)
    band = prediction_band(comparison, certain_layer, samples=5)
    assert band.delta == 0.0 and band.samples == 5
    at_estimates = popbal.run(popbal.setup(load_case(reduced_deep / "case.toml", {"case.calibration": "certain"})),
                              end_time=20.0, output_interval=1.0, progress=False).timeseries
    expected = side_by_side(comparison.full.timeseries, at_estimates)
    for column in ("droplet_count", "mean_diameter", "channel_velocity"):
        low, high = band.quantiles[column][0], band.quantiles[column][-1]
        np.testing.assert_allclose(low, expected[f"{column}_reduced"], rtol=1e-9)
        np.testing.assert_allclose(high, expected[f"{column}_reduced"], rtol=1e-9)
    widened = with_band(comparison, band).errors
    row = widened[(widened["column"] == "droplet_count") & (widened["window"] == "steady")].iloc[0]
    assert row["band_low"] == pytest.approx(row["band_high"], rel=1e-9)
    assert row["inside_band"] == (row["band_low"] <= row["mean_full"] <= row["band_high"])


def test_band_command_writes_the_band_and_refuses_a_layer_without_covariance(tmp_path, reduced_deep, capsys,
                                                                             certain_layer):
    out = tmp_path / "banded"
    assert main(["compare", REFERENCE, str(reduced_deep), "--out", str(out), "--band", certain_layer,
                 "--band-samples", "5"]) == 0
    assert "90 % band (5 popbal runs of calibration layer 'certain'" in capsys.readouterr().out
    table = read_time_series(out / "comparison.csv")
    assert {"droplet_count_band_low", "droplet_count_band_high"} <= set(table.columns)
    errors = pd.read_csv(out / "errors.csv", comment="#")
    assert {"band_low", "band_median", "band_high", "inside_band"} <= set(errors.columns)
    assert json.loads((out / "comparison.json").read_text())["band"]["layer"] == "certain"
    for args, what in ((["--band", "paper"], "--band paper: .*no \\[provenance.collision\\]"),
                       (["--band", "missing"], "--band missing: .*no calibration layer"),
                       (["--band", certain_layer, "--band-samples", "3"], "--band-samples 3: allowed"),
                       (["--band-samples", "10"], "--band-samples 10: only with --band")):
        assert main(["compare", REFERENCE, str(reduced_deep), "--out", str(tmp_path / "o"), *args]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and re.search(what, err), err
