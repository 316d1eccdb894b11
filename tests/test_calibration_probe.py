"""The closure probe (analysis.calibration.probe): it refuses the registered hold-outs before running anything, and
with the compact plume's measured radius it gives the reduced model the full runs' axis velocity in the demo's
resolved feed family, and with each run's own core and the roof's drainage law their count too
(docs/guide/reduced-model.md, the probes of the equivalent core and of the roof's drainage)."""

from __future__ import annotations

import pytest

from analysis.calibration.probe import main, parse_setting, probe
from analysis.calibration.registry import load_registry


def test_a_probe_refuses_a_registered_holdout(capsys):
    assert main(["--runs", "demo_cell_25,demo_drho_07_fine"]) == 2
    err = capsys.readouterr().err
    assert "demo_drho_07_fine is a pre-registered hold-out" in err and "Traceback" not in err


@pytest.mark.parametrize("argv, message", [(["--set", "channel_coefficient"], "is not of the form section.key=value"),
                                           (["--set", "channel_coefficient=1"], "allowed: section.key=value"),
                                           (["--runs", "nowhere"], "nowhere not stored")])
def test_a_probe_refuses_bad_options_in_one_line(argv, message, capsys):
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_values_parse_as_the_case_overrides_take_them():
    assert parse_setting("popbal.busy_partners=true") == ("popbal.busy_partners", True)
    assert parse_setting("popbal.channel_radius=0.0105") == ("popbal.channel_radius", 0.0105)
    assert parse_setting("popbal.channel_radius_form=fixed") == ("popbal.channel_radius_form", "fixed")
    assert parse_setting("popbal.plume_dilution_reynolds=none") == ("popbal.plume_dilution_reynolds", None)


def test_the_line_force_plume_at_the_measured_core_gives_the_feed_familys_axis_velocity():
    """popbal's channel at the compact plume's equivalent core (10.5 mm) under the confined line-force law at c_ch = 1
    (as derived, nothing fitted) against the full runs' window-mean axis velocity at half and twice the demo's feed:
    within 10 % (measured -1 and +2 %), where the dilution law's widening radius left twice the feed at -53 %."""
    overrides = {"popbal.channel_radius_form": "fixed", "popbal.channel_radius": 0.0105,
                 "popbal.plume_dilution_reynolds": None, "popbal.channel_coefficient": 1.0,
                 "popbal.shear_coefficient": 1.0, "popbal.bottom_layer_factor": 0.33}
    errors = probe(["demo_feed_half_fine", "demo_feed_double_fine"], overrides,
                   load_registry("data/calibration/holdouts.toml"), closures="zones_line")
    for run, error in errors.items():
        assert abs(error["channel_velocity"]) < 0.10, (run, error)


def test_given_its_measured_core_and_the_roofs_drainage_law_popbal_carries_the_resolved_demo_runs():
    """popbal under 'zones_drain' (the roof's thickness from its drainage law, k measured in the resolved
    coalescence-off run) with each resolved demo run's own equivalent core R*_t (computed here from its stored
    plume tables, analysis.groups.stored_measured_groups: 7.3-11.8 mm) as the fixed channel radius, the line-force
    law at c_ch = 1 and the return flow at T = 0.06, nothing fitted, against the full runs' window means: the five
    resolved families' count within 12 % (measured -7 to +11 %) and axis within 16 % (-4 to +15 %) (oracle probe,
    docs/guide/reduced-model.md); at the one radius of 10.5 mm the doubled viscosity's count was +20 %."""
    from analysis.groups import stored_measured_groups

    base = {"popbal.channel_radius_form": "fixed", "popbal.plume_dilution_reynolds": None,
            "popbal.channel_coefficient": 1.0, "popbal.shear_coefficient": 1.0, "popbal.bottom_layer_factor": 0.33,
            "popbal.return_flow_ratio": 1.0, "popbal.entrainment_length": 1.12, "popbal.turning_length": 0.54,
            "popbal.bottom_turning_share": 0.06}
    registry = load_registry("data/calibration/holdouts.toml")
    for run in ("demo_cell_25", "demo_feed_half_fine", "demo_feed_double_fine", "demo_visc_half_fine",
                "demo_visc_double_fine"):
        core = stored_measured_groups(f"data/reference/{run}")["moving_core_radius"]
        assert 7e-3 < core < 12e-3, (run, core)  # a compact core
        error = probe([run], {**base, "popbal.channel_radius": core}, registry, closures="zones_drain")[run]
        assert abs(error["droplet_count"]) < 0.12 and abs(error["channel_velocity"]) < 0.16, (run, error)


def test_a_coalescence_off_run_is_probed_without_the_bottom_layers_keys():
    """The transport level's coalescence-off runs are probed without a bottom layer (their floors fill), and popbal
    refuses a key that needs one there: the probe leaves the layer and each such key out for them (the floor's shear
    among them, which it once passed on, so that the probe of the default runs stopped at the first of them)."""
    from analysis.calibration.probe import BOTTOM_KEYS
    from popbal.model import setup
    from settler.cases import CaseError, load_case

    for key in BOTTOM_KEYS[1:]:  # after the layer's own factor, each key is one popbal refuses without the layer
        value = "uniform" if key.endswith("_form") else 0.5
        with pytest.raises(CaseError, match=key.split(".")[1]):
            setup(load_case("data/reference/demo_no_coalescence_fine/case.toml",
                            {"case.calibration": "none", key: value, "popbal.end_time": 1.0}))
    overrides = {"popbal.plume_core_radius": 9.47e-3, "popbal.channel_radius_factor": 0.505,  # zones_core's, rounded
                 "popbal.bottom_layer_factor": 0.35, "popbal.bottom_shear_coefficient": 0.157,
                 "popbal.bottom_turning_share": 0.15, "popbal.bottom_turning_form": "uniform"}
    errors = probe(["demo_no_coalescence_fine"], overrides, load_registry("data/calibration/holdouts.toml"),
                   closures="zones_core")
    assert set(errors) == {"demo_no_coalescence_fine"}


ZONES_CORE = {"popbal.plume_core_radius": 0.009473349689498752, "popbal.channel_radius_factor": 0.5048478001816454,
              "popbal.bottom_layer_factor": 0.3468513234083059}  # data/calibration/zones_core.toml's values


def test_the_band_table_books_each_models_matte_and_merges_in_its_bands():
    """zone_bands (probe --bands) against independent books, on a run whose stored tables start before the
    calibration's window (demo_feed_double_fine: 20-60 against 30-60 s): the full run's loads by band
    (plume_zones.csv, split by radius) times the band height are the band volumes that collisions_by_height.csv
    splits by the inlet's disk (to 1e-3), its merges over the window the time series' (exactly); popbal's merges in
    each band under the inlet (channel and roof layer) and elsewhere (outer zone and bottom layer) are those of its
    own merges_by_height table between the window's ends, and its droplets the mean of its time series' count over
    the window (to 1e-9)."""
    import numpy as np
    import pandas as pd

    import popbal
    from analysis.calibration.hierarchy import measured_closures
    from analysis.calibration.probe import BAND_OUTPUT_INTERVAL, zone_bands
    from analysis.files import read_window_header
    from settler.cases import load_case

    run, folder = "demo_feed_double_fine", "data/reference/demo_feed_double_fine"
    registry = load_registry("data/calibration/holdouts.toml")
    table = zone_bands(run, ZONES_CORE, registry, closures="zones_core")
    start, end = read_window_header(f"{folder}/collisions_by_height.csv")["window"]
    assert (start, end) == (20.0, 60.0)
    height = table["z"].iloc[1] - table["z"].iloc[0]
    collisions = pd.read_csv(f"{folder}/collisions_by_height.csv", comment="#")
    loads = (table["full_core_load"] + table["full_return_load"]) * height
    np.testing.assert_allclose(loads, collisions["volume_under_inlet"] + collisions["volume_elsewhere"], rtol=1e-3)
    series = pd.read_csv(f"{folder}/timeseries.csv", comment="#")
    in_window = (series["time"] > start) & (series["time"] <= end + 1e-9)
    full = (table["full_merges_inlet"] + table["full_merges_elsewhere"]).sum() * (end - start)
    assert full == pytest.approx(series.loc[in_window, "merges"].sum(), rel=1e-12)

    values = {**measured_closures(registry, "data/reference", "zones_core")["fixed"], **ZONES_CORE}
    case = load_case(f"{folder}/case.toml", {"case.calibration": "none", **values, "popbal.end_time": end,
                                             "popbal.output_interval": BAND_OUTPUT_INTERVAL})
    result = popbal.run(popbal.setup(case), progress=False)
    books = result.merges_by_height()
    between = books[books["time"].round(6) == end].set_index("z")[["merges_under_inlet", "merges_elsewhere"]] \
        - books[books["time"].round(6) == start].set_index("z")[["merges_under_inlet", "merges_elsewhere"]]
    layer = table["popbal_merges_layer"].to_numpy()
    under = table["popbal_merges_channel"].to_numpy() + np.where(np.arange(len(table)) == len(table) - 1, layer, 0)
    elsewhere = table["popbal_merges_outer"].to_numpy() + np.where(np.arange(len(table)) == 0, layer, 0)
    np.testing.assert_allclose(under * (end - start), between["merges_under_inlet"].to_numpy(), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(elsewhere * (end - start), between["merges_elsewhere"].to_numpy(), rtol=1e-9,
                               atol=1e-9)
    reduced = result.timeseries
    window = (reduced["time"] >= start - 1e-9) & (reduced["time"] <= end + 1e-9)
    assert table["popbal_held"].sum() == pytest.approx(reduced.loc[window, "droplet_count"].mean(), rel=1e-9)
    assert table["popbal_layer_load"].iloc[[0, -1]].min() > 0 and (table["popbal_layer_load"].iloc[1:-1] == 0).all()


@pytest.mark.parametrize("name", ["deep_w003_fine", "deep/", "./deep_fine", "../reference/demo_drho_07",
                                  "demo_feed15_visc12_fine/.", "alias"])
def test_the_band_table_refuses_a_holdout_however_named_before_running(name, tmp_path, monkeypatch):
    """A hold-out is refused by name, by a path to it and through a link to its folder under another name, before
    popbal is set up (here it would raise)."""
    import os

    import popbal
    from analysis.calibration.probe import zone_bands
    from analysis.calibration.registry import RegistryError

    def never(*args, **kwargs):
        raise AssertionError("popbal ran for a hold-out")

    monkeypatch.setattr(popbal, "setup", never)
    monkeypatch.setattr(popbal, "run", never)
    reference = "data/reference"
    if name == "alias":
        reference = tmp_path / "reference"
        reference.mkdir()
        for link in ("deep", "alias"):  # the hold-out's folder, and a link to it under another name
            os.symlink(os.path.abspath("data/reference/deep"), reference / link)
    with pytest.raises(RegistryError, match="is a pre-registered hold-out"):
        zone_bands(name, ZONES_CORE, load_registry("data/calibration/holdouts.toml"), reference, "zones_core")


def test_the_probe_skips_the_band_table_of_a_coalescence_off_run(capsys):
    argv = ["--closures", "zones_core", "--runs", "demo_no_coalescence_fine", "--bands"]
    argv += [f"--set={key}={value}" for key, value in ZONES_CORE.items()]
    assert main(argv) == 0
    assert "demo_no_coalescence_fine: no band table (coalescence off" in capsys.readouterr().out


def test_a_probe_reports_the_matte_held_in_the_slag_against_the_full_runs(monkeypatch, capsys):
    """The held-matte column is popbal's window mean of mass_in_slag over the full run's (timeseries.csv), less one:
    with popbal replaced by the full run's own time series, its mass_in_slag doubled, the column reads +100 % and the
    fitted columns, taken from the same rows, read 0."""
    import pandas as pd

    import analysis.calibration.fit as fit

    def full_series_doubled(target, case_file, values, fixed=None):
        series = pd.read_csv(case_file.parent / "timeseries.csv", comment="#")
        return series.assign(mass_in_slag=2.0 * series["mass_in_slag"])

    monkeypatch.setattr(fit, "reduced_series", full_series_doubled)
    errors = probe(["demo_feed_half_fine"], {}, load_registry("data/calibration/holdouts.toml"),
                   closures="zones_core")["demo_feed_half_fine"]
    assert errors["mass_in_slag"] == pytest.approx(1.0, rel=1e-12)
    for column in ("droplet_count", "mean_diameter", "settling_flux", "channel_velocity"):
        assert errors[column] == pytest.approx(0.0, abs=1e-9), column
    assert main(["--closures", "zones_core", "--runs", "demo_feed_half_fine"]) == 0
    line = capsys.readouterr().out.splitlines()[1]
    assert line.split()[0] == "demo_feed_half_fine" and "( +100)" in line, line
