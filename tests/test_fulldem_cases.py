"""The paper's three cases run by name with their submodels (a few fluid steps each; the long runs are the reference
runs in data/reference/)."""

import json

import pytest

import fulldem


def quiet(*args):
    pass


@pytest.mark.parametrize("name, submodels", [("cubic", ["feed", "merges", "coalescence", "exits"]),
                                             ("simple", ["feed", "merges", "coalescence", "exits"]),
                                             ("deep", ["feed", "merges", "coalescence", "reaction", "exits"])])
def test_paper_cases_run_by_name_with_their_submodels(tmp_path, name, submodels):
    setup = fulldem.setup(name, fulldem__snapshot_interval=0.0, fulldem__output_interval=0.004)
    result = fulldem.run(setup, out=tmp_path, end_time=0.012, progress=False, log=quiet)
    meta = json.loads((tmp_path / "metadata.json").read_text())
    assert meta["submodels"] == submodels and meta["submodels_missing"] == []
    ts = result.timeseries
    assert ts["droplet_count"].iloc[-1] > 0 and (abs(ts["mass_balance_error"]) < 1e-12).all()
    assert (ts["coalesced_count"] + ts["uncoalesced_count"] == ts["droplet_count"]).all()
