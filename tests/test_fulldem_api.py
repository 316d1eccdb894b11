"""The Python API of the CFD-DEM engine, used as a notebook would: set up a case, run it, read its results."""

import numpy as np
import pytest

import fulldem
from settler.cases import CaseError, load_case
from settler.output import TIME_SERIES

# the 2 ms step these end times are whole multiples of (a run ends at the first whole fluid step at or past its end)
SMALL = {"fulldem__cell_size": 0.01, "fulldem__output_interval": 0.01, "fulldem__snapshot_interval": 0.0,
         "fulldem__fluid_step": 0.002}


def quiet(*args):
    pass


def test_setup_run_load_like_a_notebook(tmp_path):
    setup = fulldem.setup("demo", **SMALL)
    assert setup.case.fulldem.cell_size == 0.01 and setup.name == "demo"
    result = fulldem.run(setup, out=tmp_path, end_time=0.03, progress=False, log=quiet)
    ts = result.timeseries
    assert list(ts.columns) == list(TIME_SERIES)
    assert ts["time"].iloc[-1] == pytest.approx(0.03) and len(ts) == 4
    # matte accounting of the finished run, read back from its folder
    assert (np.abs(ts["mass_balance_error"]) < 1e-12).all()
    drops = result.droplets()
    assert len(drops["diameter"]) == ts["droplet_count"].iloc[-1] == result.summary["droplets"]
    mass = np.sum(drops["density"] * np.pi / 6 * drops["diameter"] ** 3)
    assert mass == pytest.approx(ts["mass_in_slag"].iloc[-1], rel=1e-12)
    assert result.metadata["engine"] == "fulldem" and result.case.to_dict() == setup.case.to_dict()
    again = fulldem.load(tmp_path)
    assert again.timeseries.equals(ts)


def test_overrides_in_every_form_give_the_same_case():
    a = fulldem.setup("demo", {"slag.temperature": 1600.0})
    b = fulldem.setup("demo", ["slag.temperature=1600"])
    c = fulldem.setup("demo", slag__temperature=1600.0)
    d = fulldem.setup(load_case("demo"), slag__temperature=1600.0)
    assert a.case.to_dict() == b.case.to_dict() == c.case.to_dict() == d.case.to_dict()
    assert a.case.slag.temperature == 1600.0


def test_setup_refuses_what_the_engine_cannot_run():
    with pytest.raises(CaseError, match="fulldem.cell_size = 0.007"):
        fulldem.setup("demo", fulldem__cell_size=0.007)
    with pytest.raises(CaseError, match="slag.viscosity_reference"):
        fulldem.setup("demo", slag__viscosity_reference=-1.0)


def test_run_takes_a_name_and_overrides_and_resumes(tmp_path):
    fulldem.run("demo", out=tmp_path, end_time=0.01, progress=False, log=quiet, **SMALL)
    result = fulldem.run("demo", out=tmp_path, end_time=0.02, resume=True, progress=False, log=quiet, **SMALL)
    assert result.timeseries["time"].iloc[-1] == pytest.approx(0.02)
    with pytest.raises(TypeError, match="give them to fulldem.setup"):
        fulldem.run(fulldem.setup("demo"), out=tmp_path / "x", slag__temperature=1600.0)
