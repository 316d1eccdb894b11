"""Height profiles of a run (analysis.profiles): where the droplets are and where they merge, full beside reduced.

The band sums are checked against the totals each engine writes by other code: the droplet volume of the bands
times the matte density against the time series' mass in the slag (no reaction), the merges of the bands against
the time series' merges over the window; and ``settler compare`` writes the profiles for its steady window."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis import load_run
from analysis.profiles import band_profile, profile_comparison
from settler.cli import main

#: A stored full run of the demo case with both height tables.
FULL = Path("data/reference/demo")
WINDOW = (16.0, 25.0)


@pytest.fixture(scope="module")
def reduced_demo(tmp_path_factory):
    """popbal on the stored demo's case to 25 s on a coarse grid (a few seconds), saved as a run folder."""
    import popbal
    from settler.cases import load_case

    case = load_case(FULL / "case.toml", {"popbal.end_time": 25.0, "popbal.output_interval": 0.5,
                                          "popbal.height_cells": 20, "popbal.sections_per_doubling": 2})
    return popbal.run(popbal.setup(case), progress=False).save(tmp_path_factory.mktemp("reduced") / "demo")


def _check_sums(folder, rtol, window=WINDOW):
    run = load_run(folder)
    table, (t0, t1) = band_profile(run, window)
    assert window[0] - 1e-9 <= t0 < t1 <= window[1] + 1e-9  # the merges' span lies inside the window
    series = run.timeseries
    rows = pd.read_csv(Path(folder) / "channel_profile.csv", comment="#")
    times = np.unique(rows["time"][(rows["time"] >= window[0]) & (rows["time"] <= window[1])])
    mass = [series["mass_in_slag"][np.isclose(series["time"], t)].iloc[0] for t in times]
    assert not run.case.reaction.enabled
    assert table["droplet_volume"].sum() * run.case.matte.density == pytest.approx(np.mean(mass), rel=rtol)
    window = series[(series["time"] > t0 + 1e-9) & (series["time"] <= t1 + 1e-9)]
    merged = (table["merge_rate_under_inlet"] + table["merge_rate_elsewhere"]).sum() * (t1 - t0)
    assert merged == pytest.approx(window["merges"].sum(), rel=rtol)
    assert merged > 0.0


@pytest.mark.parametrize("window", [WINDOW, (25.0 - 25.0 / 3.0, 25.0), (16.4, 24.8)])
def test_full_run_band_sums_are_the_time_series_totals(window):
    """The stored demo: band volumes x 5100 kg/m^3 = mass in the slag, band merges = the time series' merges (the
    engine counts both per droplet; only the float32 storage differs), over windows whose ends fall between its
    snapshots (1 s apart) as compare's steady window does."""
    _check_sums(FULL, rtol=1e-6, window=window)


@pytest.mark.parametrize("window", [WINDOW, (25.0 - 25.0 / 3.0, 25.0), (16.4, 24.8)])
def test_reduced_run_band_sums_are_the_time_series_totals(reduced_demo, window):
    """popbal's bands hold its zones' droplet volume (channel, outer, roof, bottom) and merges: the same totals,
    over the same windows at its own output interval (0.5 s)."""
    _check_sums(reduced_demo, rtol=1e-6, window=window)


def test_comparison_refuses_runs_of_other_bands(tmp_path, reduced_demo):
    import popbal
    from settler.cases import load_case

    case = load_case("deep", {"popbal.end_time": 20.0, "popbal.height_cells": 20, "popbal.sections_per_doubling": 2})
    deep = popbal.run(popbal.setup(case), progress=False).save(tmp_path / "deep")
    with pytest.raises(ValueError, match="height bands differ"):
        profile_comparison(load_run(FULL), load_run(deep), WINDOW)
    with pytest.raises(ValueError, match="no channel_profile row"):
        band_profile(load_run(FULL), (40.0, 50.0))


def test_settler_compare_writes_the_profiles_of_its_steady_window(tmp_path, reduced_demo, capsys):
    out = tmp_path / "cmp"
    assert main(["compare", str(FULL), str(reduced_demo), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "height profile (reduced / full)" in printed
    table = pd.read_csv(out / "profiles.csv", comment="#")
    assert len(table) == 10 and table["z"].is_monotonic_decreasing
    info = json.loads((out / "comparison.json").read_text())["profiles"]
    steady = info["window"]
    assert steady["name"] == "steady" and steady["end"] == pytest.approx(25.0)
    assert (out / "profiles.png").stat().st_size > 10_000
    expected = profile_comparison(load_run(FULL), load_run(reduced_demo), (steady["start"], steady["end"]))
    np.testing.assert_allclose(table.to_numpy(), expected.to_numpy(), rtol=1e-12)
    assert info["merge_spans"] == {"full": [17.0, 25.0], "reduced": [17.0, 25.0]}  # rows inside 16.67-25 s
    # a comparison without the tables removes the earlier profiles from the same folder and says why
    bare = tmp_path / "bare"
    bare.mkdir()
    for name in ("timeseries.csv", "case.toml", "metadata.json"):
        (bare / name).write_bytes((Path(reduced_demo) / name).read_bytes())
    assert main(["compare", str(FULL), str(bare), "--out", str(out)]) == 0
    assert "no height profiles: no channel_profile.csv" in capsys.readouterr().out
    assert not (out / "profiles.csv").exists() and not (out / "profiles.png").exists()
