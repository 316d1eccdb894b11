"""analysis.calibrate: the fit recovers closure values from a reference made by popbal itself, its standard errors
agree with a finite-difference Hessian, a held-out case is predicted, and the calibration layer round-trips into
the presets (an explicit override still wins)."""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest
from scipy.optimize import least_squares

import popbal
from analysis import calibrate as cal
from settler import cases as cases_module
from settler.cases import DATA_DIR, CaseError, load_case
from settler.output import write_time_series

REFERENCE_DIR = DATA_DIR / "reference"

#: Coarse, short popbal settings so a model run takes a fraction of a second (5 cells, 1 section per doubling).
COARSE = {"popbal.height_cells": 10, "popbal.sections_per_doubling": 1, "popbal.time_step": 0.1,
          "popbal.end_time": 6.0, "popbal.output_interval": 0.5, "coalescence.enabled": False}
#: The "true" closure values of the synthetic references.
TRUE = {"channel_coefficient": 0.4, "axis_velocity_ratio": 1.8}
WINDOW = (2.0, 6.0)


def _synthetic_reference(folder, name, **overrides):
    """A reference folder made by popbal with TRUE closures: timeseries.csv and case.toml, as data/reference/."""
    case = load_case("simple", {**COARSE, **{f"popbal.{k}": v for k, v in TRUE.items()}, **overrides})
    result = popbal.run(popbal.setup(case), progress=False)
    out = folder / name
    out.mkdir(parents=True)
    write_time_series(result.timeseries, out / "timeseries.csv")
    # the stored case starts from the old closures, as a real reference's case.toml does
    start = case.replace(popbal__channel_coefficient=4.0 / 15.0, popbal__axis_velocity_ratio=1.0)
    (out / "case.toml").write_text(start.to_toml())
    return out


@pytest.fixture(scope="module")
def references(tmp_path_factory):
    folder = tmp_path_factory.mktemp("reference")
    _synthetic_reference(folder, "synth")
    # a held-out case at a feed three times smaller (another plume velocity, count and channel fraction)
    _synthetic_reference(folder, "synth_low", **{"feed.mass_rate": 0.0086 / 3})
    return folder


@pytest.fixture(scope="module")
def fitted(references):
    return cal.calibrate(cases=("synth",), holdout="synth_low", parameters=tuple(TRUE), reference_dir=references,
                         windows={"synth": WINDOW, "synth_low": WINDOW}, start={"channel_coefficient": 0.25,
                                                                                "axis_velocity_ratio": 1.0},
                         max_evaluations=60, progress=False)


def test_fit_recovers_known_closures_from_noise_free_data(fitted):
    """Noise-free synthetic reference: both closures recovered within 2 % from starts 38 % and 44 % off."""
    for name, true in TRUE.items():
        assert fitted.estimates[name] == pytest.approx(true, rel=0.02), name
    assert fitted.residual_rms < 0.05  # in sigma units: the model reproduces its own output


def test_held_out_case_is_predicted(fitted):
    """The held-out synthetic case (a third of the feed) comes from the same closures: its window-mean errors
    are computed for every column and, the closures being recovered, below 3 %."""
    errors = fitted.errors["synth_low"]
    assert set(errors) == set(cal.COLUMNS)
    for column in ("droplet_count", "mean_diameter", "channel_velocity"):
        assert abs(errors[column]) < 0.03, column
    assert fitted.holdout == "synth_low" and "synth_low" not in fitted.cases


def test_standard_errors_match_a_finite_difference_hessian():
    """Tiny nonlinear problem y = A exp(-k t) + noise: the Jacobian standard errors s^2 (J^T J)^-1 agree within
    5 % with s^2 H^-1, H the Hessian of 0.5 |r|^2 by central finite differences (Gauss-Newton: H ~ J^T J at a
    small-residual optimum)."""
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 4.0, 40)
    y = 2.0 * np.exp(-0.7 * t) + rng.normal(0.0, 0.02, t.size)

    def residual(x):
        return x[0] * np.exp(-x[1] * t) - y

    fit = least_squares(residual, [1.0, 1.0])
    se, correlation, _, _ = cal.parameter_uncertainty(fit.jac, fit.fun, fit.x, ["A", "k"])

    def cost(x):
        r = residual(x)
        return 0.5 * r @ r

    h = 1e-4
    hessian = np.empty((2, 2))
    for i in range(2):
        for j in range(2):
            e_i, e_j = np.eye(2)[i] * h, np.eye(2)[j] * h
            hessian[i, j] = (cost(fit.x + e_i + e_j) - cost(fit.x + e_i - e_j) - cost(fit.x - e_i + e_j)
                             + cost(fit.x - e_i - e_j)) / (4 * h * h)
    s2 = fit.fun @ fit.fun / (t.size - 2)
    expected = np.sqrt(np.diag(s2 * np.linalg.inv(hessian)))
    np.testing.assert_allclose(se, expected, rtol=0.05)
    assert correlation[0, 1] == pytest.approx(correlation[1, 0]) and abs(correlation[0, 1]) < 1.0


def test_undetermined_parameter_is_flagged():
    """A parameter the residuals do not move gets an infinite standard error and is reported as undetermined."""
    jacobian = np.array([[1.0, 0.0], [2.0, 0.0], [0.5, 0.0]])
    se, correlation, singular, _ = cal.parameter_uncertainty(jacobian, np.array([0.1, -0.1, 0.05]),
                                                             np.array([1.0, 1.0]), ["a", "b"])
    assert math.isfinite(se[0]) and se[1] == math.inf
    flags = cal.flag_undetermined(["a", "b"], np.array([1.0, 1.0]), np.array([0.0, 0.0]), np.array([2.0, 2.0]), se,
                                  correlation, singular)
    assert "b" in flags and "a" not in flags and "(all)" in flags


def test_sigma_is_the_scatter_about_the_trend():
    """sigma of a column = standard deviation of its block means about their straight line (ddof 2): a linear
    trend alone gives the floor (1 % of the mean); added +-e alternating scatter gives e * sqrt(n / (n - 2))."""
    import pandas as pd

    t = np.arange(10.0)
    blocks = pd.DataFrame({"droplet_count": 1000.0 + 50.0 * t, "mean_diameter": 5e-4 + 1e-5 * (-1.0) ** t},
                          index=t)
    sigma = cal.scatter(blocks)
    assert sigma["droplet_count"] == pytest.approx(0.01 * 1225.0)
    line = np.polyval(np.polyfit(t, blocks["mean_diameter"], 1), t)
    exact = np.sqrt(np.sum((blocks["mean_diameter"] - line) ** 2) / 8)
    assert sigma["mean_diameter"] == pytest.approx(exact, rel=1e-12) and exact > 1e-5


def test_refusals_name_the_option(references):
    with pytest.raises(cal.CalibrationError, match="--params 'nonsense': unknown nonsense; allowed"):
        cal.calibrate(cases=("synth",), holdout=None, parameters=("nonsense",), reference_dir=references,
                      windows={"synth": WINDOW}, progress=False)
    with pytest.raises(cal.CalibrationError, match="reference case 'nowhere'.*available.*synth"):
        cal.load_reference("nowhere", references)
    with pytest.raises(cal.CalibrationError, match="--steady synth=5:99: allowed 0 <= start < end"):
        cal.load_reference("synth", references, (5.0, 99.0))


def test_layer_round_trips_and_an_override_still_wins(fitted, tmp_path, monkeypatch):
    """The written layer is valid TOML holding the estimates; a case naming it takes them, an explicit override
    beats it, and case.calibration = 'none' leaves the property set's values."""
    path = cal.write_layer(fitted, tmp_path / "synthetic.toml", "settler calibrate (test)")
    layer = tomllib.loads(path.read_text())
    for name in TRUE:
        assert layer["popbal"][name] == fitted.estimates[name]
        assert layer["provenance"]["standard_errors"][name] == fitted.standard_errors[name]
    assert layer["provenance"]["holdout_case"] == "synth_low"
    assert "error_droplet_count" in layer["provenance"]["synth_low"]

    real_path = cases_module.calibration_path
    monkeypatch.setattr(cases_module, "calibration_path",
                        lambda name: path if name == "synthetic" else real_path(name))
    case = load_case("simple", {"case.calibration": "synthetic"})
    assert case.popbal.channel_coefficient == fitted.estimates["channel_coefficient"]
    assert case.popbal.axis_velocity_ratio == fitted.estimates["axis_velocity_ratio"]
    overridden = load_case("simple", {"case.calibration": "synthetic", "popbal.channel_coefficient": 0.123})
    assert overridden.popbal.channel_coefficient == 0.123
    plain = load_case("simple", {"case.calibration": "none"})
    assert plain.popbal.channel_coefficient == pytest.approx(4.0 / 15.0)
    with pytest.raises(CaseError, match="case.calibration = 'missing': no calibration layer .*available"):
        load_case("simple", {"case.calibration": "missing"})


def test_layer_carries_the_keys_held_fixed(fitted, tmp_path, monkeypatch):
    """[popbal] keys held by --fix (the channel form the estimates belong to) are written into the layer and reach a
    case that names it; keys of other sections (case.calibration) are not."""
    import dataclasses

    result = dataclasses.replace(fitted, fixed={"popbal.channel_radius_form": "flux", "popbal.shear_coefficient": 1.0,
                                                "case.calibration": "none"})
    path = cal.write_layer(result, tmp_path / "formed.toml")
    layer = tomllib.loads(path.read_text())
    assert layer["popbal"]["channel_radius_form"] == "flux"
    assert layer["popbal"]["shear_coefficient"] == 1.0
    assert "calibration" not in layer["popbal"] and "case" not in layer
    real_path = cases_module.calibration_path
    monkeypatch.setattr(cases_module, "calibration_path", lambda name: path if name == "formed" else real_path(name))
    case = load_case("simple", {"case.calibration": "formed"})
    assert case.popbal.channel_radius_form == "flux"
    assert case.popbal.channel_coefficient == fitted.estimates["channel_coefficient"]


def test_a_layer_named_by_an_override_replaces_a_resolved_case_files_values():
    """A run's resolved case.toml spells out every [popbal] key; ``case.calibration=NAME`` as an override must still
    apply the layer (over the file), and an explicit override of a key still beats the layer. (Before, the file's
    uncalibrated values silently won and the layer changed nothing.)"""
    resolved = REFERENCE_DIR / "deep_w002" / "case.toml"
    layer = tomllib.loads(cases_module.calibration_path("designed").read_text())["popbal"]
    plain = load_case(resolved)
    assert any(getattr(plain.popbal, name) != value for name, value in layer.items())
    case = load_case(resolved, {"case.calibration": "designed"})
    for name, value in layer.items():
        assert getattr(case.popbal, name) == value, name
    beaten = load_case(resolved, {"case.calibration": "designed", "popbal.shear_coefficient": 0.5})
    assert beaten.popbal.shear_coefficient == 0.5


def test_a_resolved_case_takes_another_layer_or_none_as_its_preset_does():
    """simple's stored resolved case.toml names the 'paper' layer and spells out its values. With another layer
    (or none) named by an override, every [popbal] key either layer sets comes out as for the preset given by name:
    the paper layer's values (plume_reynolds_scale among them) do not survive into 'designed', nor into 'none'."""
    resolved = REFERENCE_DIR / "simple" / "case.toml"
    keys = set()
    for name in ("paper", "designed"):
        keys |= set(tomllib.loads(cases_module.calibration_path(name).read_text())["popbal"])
    for layer in ("designed", "none"):
        from_file = load_case(resolved, {"case.calibration": layer}).popbal
        by_name = load_case("simple", {"case.calibration": layer}).popbal
        for key in sorted(keys):
            assert getattr(from_file, key) == getattr(by_name, key), (layer, key)
    assert load_case(resolved, {"case.calibration": "none"}).popbal.collision_efficiency != \
        load_case(resolved).popbal.collision_efficiency


@pytest.mark.parametrize("preset", ["simple", "cubic"])
def test_fitted_presets_are_calibrated_out_of_the_box(preset):
    """data/cases/simple.toml and cubic.toml (the fitted cases) name the 'paper' layer: its [popbal] values reach
    the case, an explicit override wins, and the furnace preset (fitted on 0.2 m boxes only) does not take it."""
    layer = tomllib.loads(cases_module.calibration_path("paper").read_text())["popbal"]
    case = load_case(preset)
    assert case.case.calibration == "paper"
    for name, value in layer.items():
        assert getattr(case.popbal, name) == value, name
    assert load_case(preset, ["popbal.collision_efficiency=0.5"]).popbal.collision_efficiency == 0.5
    assert load_case("furnace").case.calibration is None


def test_the_default_steady_windows_are_the_stored_runs_own():
    """STEADY_WINDOWS names, for each paper case, the steady window that analysis.steady.window_of finds in the stored
    run's own time series (5-s cycle means of the count within 2 %), to its end: a default left over from a set that
    is no longer stored would score a run in its start-up."""
    from analysis import load_run
    from analysis.steady import window_of

    for name, window in cal.STEADY_WINDOWS.items():
        found, steady = window_of(load_run(f"data/reference/{name}").timeseries)
        assert steady and found == pytest.approx(window), name
