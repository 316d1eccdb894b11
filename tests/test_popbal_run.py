"""popbal runs: every preset sets up and runs, outputs follow the shared schema, the command line writes them."""

import json

import numpy as np
import pytest

import popbal
from popbal import ideal
from settler.cases import list_presets
from settler.cli import main
from settler.output import TIME_SERIES, read_time_series

# a few coarse settings so that every preset runs in well under a second
QUICK = {"popbal.height_cells": 10, "popbal.sections_per_doubling": 1}


@pytest.mark.parametrize("name", list_presets())
def test_every_preset_sets_up_and_runs(name):
    model = popbal.setup(name, QUICK)
    assert model.name == name
    short = 0.02 * model.stop_time
    result = popbal.run(model, end_time=short, output_interval=short / 4)
    ts = result.timeseries
    assert list(ts.columns) == list(TIME_SERIES)
    assert ts.time.iloc[-1] == pytest.approx(short)
    assert np.abs(ts.mass_balance_error).max() < 1e-10
    assert ts.mass_fed.iloc[-1] > 0.0 and ts.droplet_count.iloc[-1] > 0.0
    for column in ("max_cell_reynolds", "max_cfl", "max_overlap_ratio", "wall_time"):
        assert ts[column].isna().all()
    shape = (ts.shape[0], len(popbal.ZONES), model.cells, model.grid.size)
    assert result.number_density.shape == shape and result.diameter.shape == shape
    frame = result.size_distribution()
    assert set(frame.zone) <= set(popbal.ZONES) and len(frame) == len(popbal.ZONES) * model.cells * model.grid.size


def test_command_line_writes_the_outputs(tmp_path, capsys):
    out = tmp_path / "simple"
    assert main(["reduced", "simple", "popbal.end_time=3", "popbal.output_interval=0.5", "--out", str(out),
                 "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "settled" in printed and str(out) in printed
    ts = read_time_series(out / "timeseries.csv")
    assert list(ts.columns) == list(TIME_SERIES) and len(ts) == 7
    arrays = np.load(out / "distribution.npz")
    assert set(arrays.files) == set(popbal.DISTRIBUTION_ARRAYS)
    meta = json.loads((out / "metadata.json").read_text())
    assert meta["engine"] == "popbal" and meta["distribution_arrays"]["number_density"]["unit"] == "1/m^3"
    assert "steady channel velocity u_c" in meta["start_up"]
    assert "[popbal]" in (out / "case.toml").read_text()


def test_command_line_errors_name_the_key(tmp_path, capsys):
    assert main(["reduced", "simple", "popbal.height_cells=2", "--out", str(tmp_path)]) == 2
    assert "popbal.height_cells = 2" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:  # argparse refuses the option (settler.arguments.seconds)
        main(["reduced", "simple", "--end-time", "0", "--out", str(tmp_path)])
    assert exit_info.value.code == 2
    assert "argument --end-time: 0: allowed" in capsys.readouterr().err


def test_progress_lines_on_request(capsys):
    popbal.run("simple", end_time=0.5, progress=True, progress_interval=0.0, **QUICK_KW)
    err = capsys.readouterr().err
    assert "popbal simple: t = " in err and "done" in err


QUICK_KW = {k.replace(".", "__"): v for k, v in QUICK.items()}


def test_horizontal_column_loses_what_cannot_settle_in_the_residence_time():
    """Furnace without coalescence: a section whose droplets cannot cross the layer in the residence time is lost,
    one that crosses it well before is not (the plug-flow column's loss)."""
    result = popbal.run("furnace", coalescence__enabled=False, popbal__height_cells=50, popbal__time_step=120.0,
                        popbal__output_interval=3600.0)
    model = result.model
    loss = result.loss_by_size()
    v = model.velocity_table[:, 0]
    fed = loss.fed_mass > 0
    slow = fed & (v * model.residence_time < 0.5 * model.case.geometry.height)
    fast = fed & (v * (model.residence_time - model.feed_end) > 2.0 * model.case.geometry.height)
    assert slow.any() and fast.any()
    exact = 1.0 - ideal.top_entry_column_capture(v, model.residence_time, model.case.geometry.height, model.feed_end)
    assert np.all(exact[slow] == 1.0) and np.all(exact[fast] == 0.0)
    assert np.all(loss.loss_fraction[slow] > 0.999) and np.all(loss.loss_fraction[fast] < 1e-3)
    # ideal settlers for comparison: Hazen's plug flow captures part of the slow classes, which enter spread over H
    assert np.all(ideal.plug_flow_capture(v[slow], model.residence_time, model.case.geometry.height) < 0.5)
    assert np.all(ideal.mixed_capture(v, 1.0, 1.0) <= ideal.plug_flow_capture(v, 1.0, 1.0))
