"""``settler sweep --engine full`` and run sets (``--set FILE``): each point a fulldem run in its hash-keyed folder,
its metrics those of its own time series, an interrupted point resumed from its checkpoint to the same end, and a
refused set file named key by key."""

import json
import math

import numpy as np
import pandas as pd
import pytest

from analysis.sweep import DONE_FILE, load_run_set, point_hash, summarize, sweep, sweep_set
from settler.cases import CaseError, load_case
from settler.output import read_time_series

#: A demo run of 5 fluid steps of 4 ms with feed and coalescence: seconds once the kernels are compiled.
SHORT = {"fulldem.end_time": 0.02, "fulldem.output_interval": 0.004, "fulldem.snapshot_interval": 0.01}


def row_hash(result, name):
    return result.table.set_index("name").loc[name, "hash"]


def _write_set(tmp_path, body: str):
    path = tmp_path / "set.toml"
    path.write_text(body)
    return path


def _short_set(tmp_path):
    overrides = ", ".join(f'"{k}" = {v}' for k, v in SHORT.items())
    return _write_set(tmp_path, f"""
[set]
description = "two short demo runs"

[runs.base]
case = "demo"
overrides = {{ {overrides} }}
family = "feed"

[runs.double]
case = "demo"
overrides = {{ {overrides}, "feed.mass_rate" = 0.004 }}
family = "feed"
purpose = "twice the feed"
snapshots = 0
""")


def test_a_run_set_of_full_runs_records_each_runs_own_metrics(tmp_path):
    path = _short_set(tmp_path)
    result = sweep_set(path, "full", tmp_path / "out", workers=0, progress=False, command_line="test")
    assert list(result.table["name"]) == ["base", "double"] and (result.table["status"] == "done").all()
    assert result.ran == 2 and result.failed == 0
    for row in result.table.to_dict("records"):
        folder = tmp_path / "out" / "points" / row["hash"]
        series = read_time_series(folder / "timeseries.csv")
        assert series["time"].iloc[-1] == pytest.approx(0.02)
        expected = summarize(series)
        for key, value in expected.items():
            assert row[key] == pytest.approx(value, rel=1e-12, nan_ok=True)
        meta = json.loads((folder / "metadata.json").read_text())
        assert meta["engine"] == "fulldem" and "run " + row["name"] in meta["command"]
        assert set(meta["engine_trees"]) == {"fulldem", "popbal", "settler"}
    fed = result.table.set_index("name")
    # twice the feed rate places twice the matte over the same 0.02 s, to one droplet's mass
    base = read_time_series(tmp_path / "out" / "points" / fed.loc["base", "hash"] / "timeseries.csv")
    double = read_time_series(tmp_path / "out" / "points" / fed.loc["double", "hash"] / "timeseries.csv")
    droplet = 1e-3 ** 3 * math.pi / 6 * 5200.0
    assert double["mass_fed"].iloc[-1] == pytest.approx(2 * base["mass_fed"].iloc[-1], abs=3 * droplet)
    # a second run of the command reads the finished runs back
    again = sweep_set(path, "full", tmp_path / "out", workers=0, progress=False)
    assert again.ran == 0 and again.skipped == 2 and again.table["resumed"].all()
    info = json.loads((tmp_path / "out" / "sweep.json").read_text())
    assert info["engine"] == "full" and set(info["runs"]) == {"base", "double"}
    # stored as references under their names, each with the command that regenerates it alone
    from analysis import load_run
    from analysis.reference_set import store_set

    stored = store_set(tmp_path / "out", path, tmp_path / "reference")
    assert set(stored) == {"base", "double"}
    for name, folder in stored.items():
        run = load_run(folder)
        assert run.reference["command"] == f"settler sweep --set {path} --engine full --only {name}"
        assert run.reference["dirty"] is not None and run.reference["engine_trees"] == meta["engine_trees"]
        assert str(tmp_path / "out") not in json.dumps(run.reference)  # the sweep's folders are not named
        first = (folder / "case.toml").read_text().splitlines()[0]
        assert first == "# resolved case; loaded from data/cases/demo.toml", first
        made = tmp_path / "out" / "points" / row_hash(result, name) / "case.toml"
        assert run.case.to_dict() == load_case(made).to_dict()  # only the comment changed
        # the collisions by height, measured on the run folder with its whole slag grid (analysis.band_efficiency)
        table = pd.read_csv(folder / "collisions_by_height.csv", comment="#")
        assert len(table) == 10 and np.isfinite(table[["shear_under_inlet", "shear_elsewhere"]].to_numpy()).all()
    # the set's 'snapshots' key: double keeps none (and says so), base the command's default of 2
    assert (stored["double"] / "snapshots.npz").exists() is False
    assert load_run(stored["double"]).reference["snapshots"]["stored"] == 0
    assert any("0 snapshots asked for" in note for note in load_run(stored["double"]).reference["notes"])
    assert load_run(stored["base"]).reference["snapshots"]["stored"] == 2


def test_an_interrupted_full_point_resumes_from_its_checkpoint(tmp_path):
    """A point left with a checkpoint at 0.012 s and no done.json (its worker killed) continues from there: the
    resumed run says so in its log, reaches the end time, and its time series matches an uninterrupted run's."""
    from fulldem.driver import run_case

    case = load_case("demo", [f"{k}={v}" for k, v in SHORT.items()])
    digest = point_hash(case, "full")
    folder = tmp_path / "out" / "points" / digest
    run_case(case, folder, end_time=0.012, progress=False, log=lambda text: None)
    assert not (folder / DONE_FILE).exists()
    result = sweep(case, {}, out=tmp_path / "out", workers=0, progress=False, plots=False, engine="full")
    assert result.table["hash"].tolist() == [digest] and result.table["status"].tolist() == ["done"]
    assert "resumed from" in (folder / "run.log").read_text()
    resumed = read_time_series(folder / "timeseries.csv")
    whole = run_case(case, tmp_path / "whole", progress=False, log=lambda text: None)
    columns = [c for c in resumed.columns if c != "wall_time"]
    np.testing.assert_allclose(resumed[columns].to_numpy(), whole[columns].to_numpy(), rtol=1e-12, atol=0.0)


def test_full_and_reduced_points_of_one_case_have_their_own_folders():
    case = load_case("demo")
    assert point_hash(case) != point_hash(case, "full")
    assert point_hash(case, "full") == point_hash(load_case("demo"), "full")


@pytest.mark.parametrize("body, message", [
    ('[runs.a]\ncase = "demo"\ncolour = "red"\n', "unknown key(s) colour"),
    ('[runs.a]\noverrides = {}\n', "case = None"),
    ('[runs."a b"]\ncase = "demo"\n', "the name must be"),
    ('[runs.a]\ncase = "demo"\noverrides = { "slag.viscosity_reference" = -1.0 }\n', "run 'a'"),
    ('[runs.a]\ncase = "demo"\ndroplets = "none.csv"\n', "no such file"),
    ('[runs.a]\ncase = "demo"\nsnapshots = -1\n', "snapshots = -1: allowed: a whole number >= 0"),
    ('[runs.a]\ncase = "demo"\nsnapshots = 1.5\n', "snapshots = 1.5: allowed"),
    ('[set]\n', "no [runs.NAME] tables"),
    ('[runz.a]\ncase = "demo"\n', "unknown table(s) runz"),
])
def test_a_bad_run_set_is_refused_naming_the_key(tmp_path, body, message):
    with pytest.raises(CaseError, match=message.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[")
                       .replace("]", r"\]")):
        load_run_set(_write_set(tmp_path, body))


def test_settler_sweep_set_refuses_a_case_and_only_without_set(tmp_path, capsys):
    from settler.cli import main

    path = _short_set(tmp_path)
    assert main(["sweep", "demo", "--set", str(path), "--out", str(tmp_path / "o")]) == 2
    assert "allowed: --set alone" in capsys.readouterr().err
    assert main(["sweep", "demo", "feed.mass_rate=0.001,0.002", "--only", "base", "--out", str(tmp_path / "o")]) == 2
    assert "--only base: allowed only with --set" in capsys.readouterr().err
    assert main(["sweep", "--set", str(path), "--only", "nothing", "--out", str(tmp_path / "o")]) == 2
    assert "--only nothing: not in" in capsys.readouterr().err
    assert main(["sweep", "--engine", "full", "--out", str(tmp_path / "o")]) == 2
    assert "no CASE" in capsys.readouterr().err


def test_status_reads_where_each_run_stands_without_running_anything(tmp_path, capsys):
    """--status on a set whose first run is done and whose second has a time series at 0.01 s (wall time growing
    5 s per 0.002 s simulated): done / started with its pace (2 500 s/s) and time to go (0.01 s left: 25 s); nothing
    is run (no new folder appears); --status without --set is refused."""
    import pandas as pd

    from analysis.sweep import POINTS
    from analysis.sweep.runset import format_status, set_status
    from settler.cli import main

    path = _short_set(tmp_path)
    out = tmp_path / "o"
    runs = {r.name: r for r in load_run_set(path).runs}
    base, double = (out / POINTS / point_hash(runs[n].case, "full") for n in ("base", "double"))
    base.mkdir(parents=True)
    double.mkdir(parents=True)
    (base / DONE_FILE).write_text(json.dumps({"status": "done", "hash": base.name}))
    t = np.arange(0.0, 0.0101, 0.002)
    pd.DataFrame({"time": t, "droplet_count": 1.0, "wall_time": 10.0 + 2500.0 * t}).to_csv(
        double / "timeseries.csv", index=False)
    table = set_status(path, "full", out, now=(double / "timeseries.csv").stat().st_mtime + 120.0).set_index("name")
    assert table.loc["base", "state"] == "done" and table.loc["base", "remaining"] == 0.0
    assert table.loc["double", "state"] == "started" and table.loc["double", "time"] == pytest.approx(0.01)
    assert table.loc["double", "pace"] == pytest.approx(2500.0)
    assert table.loc["double", "remaining"] == pytest.approx(25.0)
    assert table.loc["double", "updated"] == pytest.approx(120.0, abs=1.0)
    text = format_status(table.reset_index(), workers=2)
    assert "1 of 2 runs done" in text and "2 min ago" in text
    assert main(["sweep", "--set", str(path), "--engine", "full", "--out", str(out), "--status"]) == 0
    assert "started" in capsys.readouterr().out
    assert sorted(p.name for p in (out / POINTS).iterdir()) == sorted([base.name, double.name])
    assert main(["sweep", "demo", "feed.mass_rate=0.001,0.002", "--status", "--out", str(out)]) == 2
    assert "--status: allowed only with --set" in capsys.readouterr().err
