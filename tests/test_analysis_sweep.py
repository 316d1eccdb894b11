"""analysis.sweep: axes parsed and refused in one line naming the key; grid sizes; point hashes stable across
processes and distinct; a rerun skips finished points (runs counted) and redoes unfinished ones; a failing point is
recorded and makes the command exit 3; a 2-worker LocalCluster gives popbal's own numbers; SALib designs stay in
their bounds and Sobol indices of a linear function match the analytic ones; the quick furnace study runs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import xarray as xr

import popbal
from analysis import sweep as sw
from settler.cases import CaseError, load_case
from settler.cli import main as settler_main

ROOT = Path(__file__).resolve().parents[1]
#: A simple-case point that runs in a few milliseconds (10 cells, 1 section per doubling, 1 s simulated).
TINY = ["popbal.end_time=1", "popbal.output_interval=0.5", "popbal.height_cells=10",
        "popbal.sections_per_doubling=1", "popbal.time_step=0.1"]
#: A furnace point with loss > 0 that runs in a fraction of a second (the quick study resolution).
FURNACE_TINY = {**sw.FURNACE_BASE, **sw.FURNACE_QUICK}


# ------------------------------------------------------------------------------------------------------------ axes
def test_range_is_linear_inclusive_and_log_is_geometric():
    axis = sw.parse_axis("slag.temperature=1500:1600:5")
    assert axis.values == pytest.approx([1500.0, 1525.0, 1550.0, 1575.0, 1600.0], rel=1e-15)
    log = sw.parse_axis("popbal.collision_efficiency=0.01:1:3:log")
    assert log.values == pytest.approx([0.01, 0.1, 1.0], rel=1e-14)
    assert log.log and log.low == 0.01 and log.high == 1.0
    bare = sw.parse_axis("geometry.height=0.5:1.5")
    assert bare.values is None and (bare.low, bare.high) == (0.5, 1.5)
    assert sw.parse_axis("popbal.height_cells=10:30:3").values == (10, 20, 30)  # integer key: integers


def test_lists_numbers_booleans_names_and_list_values():
    assert sw.parse_axis("slag.temperature=1500,1550.5").values == (1500, 1550.5)
    assert sw.parse_axis("coalescence.enabled=true,false").values == (True, False)
    assert sw.parse_axis("drag.law=stokes,schiller_naumann").values == ("stokes", "schiller_naumann")
    lists = sw.parse_axis("feed.table_diameters=[1e-4, 2e-4],[3e-4, 4e-4]")
    assert lists.values == ([1e-4, 2e-4], [3e-4, 4e-4])
    assert sw.parse_axis("slag.temperature=1500").fixed


@pytest.mark.parametrize("text, named", [
    ("slag.temprature=1500:1600:3", "slag.temprature"),   # unknown key
    ("slagg.temperature=1,2", "slagg.temperature"),        # unknown section
    ("temperature=1,2", "temperature"),                    # no section
    ("slag.temperature=hot:1600:3", "'hot'"),              # a is not a number
    ("slag.temperature=1500:1600:0", "n = '0'"),           # n < 1
    ("slag.temperature=1500:1600:3:cubic", "'cubic'"),     # unknown scale
    ("slag.temperature=0:1600:3:log", "a > 0"),            # log of 0
    ("slag.temperature=-5,1500", "-5"),                    # out of range (validated on the case)
    ("slag.temperature=1500,1500", "twice"),               # repeated value
    ("popbal.height_cells=10:20:4", "integers"),           # 10, 13.3, ...: not integers
    ("coalescence.enabled=0:1:2", "numeric key"),          # a range of a boolean key
    ("drag.law=stokes,newton", "newton"),                  # not a registered law
    ("slag.temperature=", "section.key=v1,v2"),            # no values
])
def test_bad_axes_refused_naming_key_and_value(text, named):
    with pytest.raises(CaseError) as info:
        sw.parse_axes([text], load_case("simple"))
    message = str(info.value)
    key = text.split("=")[0]
    assert key in message and named in message
    assert "\n" not in message


def test_grid_is_the_full_factorial_and_fixed_values_are_not_swept():
    axes = sw.parse_axes(["slag.temperature=1500:1600:3", "coalescence.enabled=true,false",
                          "popbal.collision_efficiency=0.25,0.5,0.75,1", "popbal.end_time=2"])
    design = sw.build_design(axes, "grid")
    assert len(design.table) == 3 * 2 * 4
    assert list(design.table.columns) == ["slag.temperature", "coalescence.enabled", "popbal.collision_efficiency"]
    assert len(design.table.drop_duplicates()) == 24
    assert design.fixed == {"popbal.end_time": 2}
    with pytest.raises(CaseError, match="a grid needs the number of values"):
        sw.build_design(sw.parse_axes(["slag.temperature=1500:1600"]), "grid")
    with pytest.raises(CaseError, match="--samples 8"):
        sw.build_design(axes, "grid", samples=8)


# ---------------------------------------------------------------------------------------------------------- hashes
def test_point_hash_is_stable_across_processes_and_distinct():
    a = sw.point_hash(load_case("simple", {"slag.temperature": 1500}))
    b = sw.point_hash(load_case("simple", ["slag.temperature=1500.0"]))  # the same case given another way
    c = sw.point_hash(load_case("simple", {"slag.temperature": 1500.0001}))
    assert a == b and a != c and len(a) == 16
    code = ("from analysis.sweep import point_hash; from settler.cases import load_case; "
            "print(point_hash(load_case('simple', {'slag.temperature': 1500})))")
    other = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True,
                           env={"PYTHONPATH": str(ROOT), "PYTHONHASHSEED": "12345", "PATH": "/usr/bin:/bin"})
    assert other.stdout.strip() == a
    grid = sw.build_design(sw.parse_axes(["slag.temperature=1500:1600:4", "feed.mass_rate=0.1,0.2"]), "grid")
    hashes = {sw.point_hash(load_case("simple", row)) for row in grid.table.to_dict("records")}
    assert len(hashes) == 8


# ---------------------------------------------------------------------------------------------------------- resume
def test_rerun_skips_finished_points_and_redoes_unfinished(tmp_path, monkeypatch):
    calls = []
    original = popbal.run

    def counting(model, *args, **kwargs):
        calls.append(model.case.popbal.collision_efficiency)
        return original(model, *args, **kwargs)

    monkeypatch.setattr(popbal, "run", counting)
    axes = TINY + ["popbal.collision_efficiency=0.5,1"]
    first = sw.sweep("simple", axes, out=tmp_path, workers=0, progress=False, plots=False)
    assert (first.ran, first.skipped) == (2, 0) and sorted(calls) == [0.5, 1.0]
    for digest in first.table["hash"]:
        assert json.loads((tmp_path / "points" / digest / "done.json").read_text())["status"] == "done"
        assert (tmp_path / "points" / digest / "timeseries.csv").is_file()  # popbal's own save
    calls.clear()
    second = sw.sweep("simple", TINY + ["popbal.collision_efficiency=0.5,0.75,1"], out=tmp_path, workers=0,
                      progress=False, plots=False)
    assert calls == [0.75] and (second.ran, second.skipped) == (1, 2)
    assert second.table["resumed"].tolist() == [True, False, True]
    pd.testing.assert_frame_equal(first.table.drop(columns="resumed").iloc[[0, 1]].reset_index(drop=True),
                                  second.table.drop(columns="resumed").iloc[[0, 2]].reset_index(drop=True)
                                  .assign(point=[0, 1]))
    # a point whose done-marker is missing (killed while saving) runs again
    (tmp_path / "points" / second.table["hash"][1] / "done.json").unlink()
    calls.clear()
    third = sw.sweep("simple", TINY + ["popbal.collision_efficiency=0.5,0.75,1"], out=tmp_path, workers=0,
                     progress=False, plots=False)
    assert calls == [0.75] and third.ran == 1


# ---------------------------------------------------------------------------------------------------------- failure
def test_failing_point_is_recorded_and_the_command_exits_3(tmp_path, capsys):
    # with the 'inlet' channel form (the simple preset's calibration uses 'flux', where any factor fits), a channel
    # wider than the 0.2 m box passes the case schema but popbal.setup refuses it: a failure in the task
    status = settler_main(["sweep", "simple", *TINY, "popbal.channel_radius_form=inlet",
                           "popbal.channel_radius_factor=1,10", "--workers", "0",
                           "--out", str(tmp_path), "--quiet"])
    assert status == 3
    assert "1 of 2 points failed" in capsys.readouterr().err
    table = pd.read_csv(tmp_path / "sweep.csv", comment="#")
    assert table["status"].tolist() == ["done", "failed"]
    assert "channel_radius_factor" in table["error"][1] and np.isnan(table["matte_loss"][1])
    assert np.isfinite(table["settled_fraction"][0])
    failed = tmp_path / "points" / table["hash"][1]
    assert (failed / "error.json").is_file() and not (failed / "done.json").exists()
    assert not (tmp_path / "sensitivity.csv").exists()


def test_command_refuses_a_bad_axis_in_one_line(tmp_path, capsys):
    status = settler_main(["sweep", "simple", "slag.temprature=1500:1600:3", "--out", str(tmp_path / "s")])
    err = capsys.readouterr().err.strip()
    assert status == 2 and "slag.temprature" in err and len(err.splitlines()) == 1
    assert settler_main(["sweep", "simple", "slag.temperature=1500,1600", "--workers", "-1", "--out",
                         str(tmp_path / "s")]) == 2
    assert "--workers -1" in capsys.readouterr().err


# --------------------------------------------------------------------------------------------------- dask cluster
def test_local_cluster_sweep_gives_popbal_numbers(tmp_path):
    temperatures = [1500.0, 1550.0, 1600.0]
    result = sw.sweep("furnace", {**{k: str(v) for k, v in FURNACE_TINY.items()},
                                  "slag.temperature": temperatures}, out=tmp_path, workers=2, progress=False)
    assert result.failed == 0 and result.ran == 3
    for row in result.table.to_dict("records"):
        direct = popbal.run(popbal.setup("furnace", {**FURNACE_TINY, "slag.temperature": row["slag.temperature"]}),
                            progress=False).timeseries
        last = direct.iloc[-1]
        assert row["matte_loss"] == pytest.approx(last["mass_lost"] / last["mass_fed"], rel=1e-12)
        assert row["settled_fraction"] == pytest.approx(last["mass_settled"] / last["mass_fed"], rel=1e-12)
        holding = direct[direct["droplet_count"] > 0].iloc[-1]
        assert row["mean_diameter"] == pytest.approx(holding["mean_diameter"], rel=1e-12)
        assert row["sauter_diameter"] == pytest.approx(holding["sauter_diameter"], rel=1e-12)
    losses = result.table["matte_loss"].to_numpy()
    assert np.all(losses > 0) and np.all(np.diff(losses) < 0)  # hotter slag, lower viscosity, less loss
    on_disk = xr.open_dataset(tmp_path / "sweep.nc", engine="h5netcdf")
    assert on_disk["matte_loss"].dims == ("slag.temperature",)
    np.testing.assert_array_equal(on_disk["matte_loss"].values, losses)
    assert on_disk["mean_diameter"].attrs["units"] == "m"
    assert (tmp_path / "sweep_slag.temperature.png").stat().st_size > 1000


# ---------------------------------------------------------------------------------------------------------- SALib
@pytest.mark.parametrize("design, samples, points", [("lhs", 10, 10), ("sobol", 8, 8 * 5), ("morris", 4, 4 * 4)])
def test_sampled_designs_stay_within_bounds(design, samples, points):
    axes = sw.parse_axes(["slag.temperature=1500:1600", "popbal.collision_efficiency=0.01:1:5:log",
                          "popbal.height_cells=10:40", "popbal.end_time=2"])
    plan = sw.build_design(axes, design, samples, seed=3)
    assert len(plan.table) == points
    t, e, cells = (plan.table[k] for k in ("slag.temperature", "popbal.collision_efficiency", "popbal.height_cells"))
    assert t.between(1500, 1600).all() and e.between(0.01, 1.0).all() and cells.between(10, 40).all()
    assert all(isinstance(v, int) for v in cells)
    assert plan.problem["names"][1] == "log10(popbal.collision_efficiency)"
    again = sw.build_design(axes, design, samples, seed=3)
    pd.testing.assert_frame_equal(plan.table, again.table)  # deterministic for a seed


def test_sampled_design_refusals():
    axes = sw.parse_axes(["slag.temperature=1500:1600"])
    with pytest.raises(CaseError, match="power of 2"):
        sw.build_design(axes, "sobol", 10)
    with pytest.raises(CaseError, match="coalescence.enabled"):
        sw.build_design(sw.parse_axes(["slag.temperature=1500:1600", "coalescence.enabled=true,false"]), "lhs")


def test_sobol_indices_of_a_linear_function_match_the_analytic_values():
    # y = 2 x1 + x2 (+ 0 x3) with uniform x on [0, 1]: S1 = ST = (4/5, 1/5, 0)
    axes = sw.parse_axes(["slag.temperature=0:1", "feed.mass_rate=0:1", "geometry.height=0:1"])
    plan = sw.build_design(axes, "sobol", 1024, seed=1)
    x = plan.table.to_numpy()
    y = 2.0 * x[:, 0] + x[:, 1]
    table = plan.table.assign(matte_loss=y, settled_fraction=1.0 - y / 3.0, mean_diameter=x[:, 2], status="done")
    frame, note = sw.sensitivity(table, plan, seed=1)
    loss = frame[frame["metric"] == "matte_loss"].set_index("parameter")
    np.testing.assert_allclose(loss["S1"], [0.8, 0.2, 0.0], atol=0.03)
    np.testing.assert_allclose(loss["ST"], [0.8, 0.2, 0.0], atol=0.03)
    assert loss["rank"].tolist() == [1, 2, 3] and note == ""
    size = frame[frame["metric"] == "mean_diameter"].set_index("parameter")
    assert size.loc["geometry.height", "ST"] == pytest.approx(1.0, abs=0.03)


# -------------------------------------------------------------------------------------------------- furnace study
def test_quick_furnace_study_ranks_every_axis(tmp_path):
    results = sw.furnace_study(tmp_path, quick=True, progress=False)
    ranking = results["ranking"]
    assert sorted(ranking["parameter"]) == sorted(sw.FURNACE_AXES)
    assert ranking["morris_log10_matte_loss_mu_star"].is_monotonic_decreasing
    assert ranking["morris_matte_loss_mu_star"].notna().all()
    for key, trend in results["trends"].items():
        assert len(trend.table) == 3 and (trend.table["status"] == "done").all()
        low, high, source = sw.FURNACE_AXES[key]
        assert trend.table[key].min() == pytest.approx(low) and trend.table[key].max() == pytest.approx(high)
        assert source.startswith(("[lit]", "[chosen]", "[derived]"))
    assert results["figure"].is_file() and (tmp_path / "morris" / "sensitivity.png").is_file()
    # one folder per distinct point: the baseline, in several trends, ran once
    tables = [t.table for t in results["trends"].values()] + [results["morris"].table]
    hashes = set(pd.concat(tables)["hash"])
    assert len(list((tmp_path / "points").iterdir())) == len(hashes) < sum(len(t) for t in tables)


@pytest.mark.parametrize("key, values, factor, label", [
    ("feed.mean_diameter", [1e-4, 3e-4], 1e6, "feed mean diameter [µm]"),
    ("geometry.inlet_diameter", [0.02, 0.075], 1e3, "geometry inlet diameter [mm]"),
    ("geometry.height", [0.5, 2.0], 1.0, "geometry height [m]"),
    ("slag.temperature", [1493.0, 1593.0], 1.0, "slag temperature [K]"),
])
def test_plot_axes_name_keys_in_words_and_lengths_in_readable_units(key, values, factor, label):
    """Trends plots: no case key as a label, no diameter in m with a 1e-4 offset."""
    from analysis.sweep.results import axis_scale

    assert axis_scale(key, values) == (factor, label)
