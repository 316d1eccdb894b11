"""The hierarchical calibration's parts against independent references: the standard error of an autocorrelated
window mean against Monte Carlo replicates, the fit and its gate against linear models whose answers are known
(identifiable, and a product only), the discrepancy term against chi^2 = m - p, and the registry's refusals."""

import math

import numpy as np
import pandas as pd
import pytest

from analysis.calibration.fit import fit_level
from analysis.calibration.registry import RegistryError, load_registry, refuse_holdouts
from analysis.calibration.targets import (TARGET_COLUMNS, Target, effective_count, scored_window, window_means, window_of,
                                        within_run_errors)

COLUMNS = tuple(TARGET_COLUMNS)


def _ar1(rng, n, phi, scale):
    x = np.empty(n)
    x[0] = rng.normal(0.0, scale / math.sqrt(1.0 - phi**2))
    for i in range(1, n):
        x[i] = phi * x[i - 1] + rng.normal(0.0, scale)
    return x


def test_window_mean_error_of_an_autocorrelated_series_matches_its_replicates():
    """An AR(1) series (phi = 0.6) of 80 one-second blocks: the mean over replicates of the estimated standard
    error of the window mean lies within 15 % of the replicates' actual scatter of that mean (treating the blocks as
    independent would underestimate it by sqrt((1 + phi) / (1 - phi)) = 2)."""
    rng = np.random.default_rng(7)
    n, phi = 80, 0.6
    means, estimates = [], []
    t = np.arange(1.0, n + 1.0)
    for _ in range(300):
        count = 1000.0 + _ar1(rng, n, phi, 10.0)
        frame = pd.DataFrame({"time": t, "droplet_count": count, "mean_diameter": 1e-3 + 0.0 * t,
                              "channel_velocity": 0.05 + 0.0 * t, "mass_settled": 1e-3 * t})
        errors, counts = within_run_errors(frame, (0.0, float(n)))
        means.append(count.mean())
        estimates.append(errors["droplet_count"])
    actual = float(np.std(means, ddof=1))
    assert np.mean(estimates) == pytest.approx(actual, rel=0.15)
    assert effective_count(80, 0.6) == pytest.approx(20.0)


def test_the_scored_window_is_the_steady_windows_last_part_so_a_late_settling_start_is_not_scored():
    """A run whose droplet count is steady from 30 s while nothing reaches the floor before 45 s (deep's feed), then
    settles 0.1 g/s to its end at 120 s: the scored window is 90-120 s, and the settling flux over it is the late
    slope 1e-4 kg/s to 1e-9 (the window's first 30 s would give 1e-4 x 15 / 30, half of it)."""
    t = np.arange(0.0, 120.05, 0.1)
    count = np.where(t < 30.0, 5000.0 * t / 30.0, 5000.0)
    settled = 1e-4 * np.clip(t - 45.0, 0.0, None)
    frame = pd.DataFrame({"time": t, "droplet_count": count, "mean_diameter": 6e-4 + 0.0 * t,
                          "channel_velocity": 6e-3 + 0.0 * t, "mass_settled": settled})
    (start, end), steady = scored_window(frame, 30.0)
    assert steady and (start, end) == (pytest.approx(90.0), pytest.approx(120.0))
    assert window_means(frame, (start, end))["settling_flux"] == pytest.approx(1e-4, rel=1e-9)
    assert window_of(frame)[0][0] <= 35.0  # the count's own steady window starts early: the cap takes its end


def _targets(model, truth, names, rng, relative=0.01):
    out = []
    for name in names:
        exact = model(Target(name, (0, 1), True, {}, {}), None, truth, None)
        se = {c: relative * abs(v) for c, v in exact.items()}
        out.append(Target(name=name, window=(0.0, 1.0), steady=True,
                          means={c: v + rng.normal(0.0, se[c]) for c, v in exact.items()}, standard_errors=se))
    return out


COVARIATES = {f"r{k}": (1.0 + k, 2.0 - 0.3 * k) for k in range(4)}


def _linear(target, case_file, values, fixed):
    x, y = COVARIATES[target.name]
    a, b = values["channel_coefficient"], values["shear_coefficient"]
    return {c: (a * x + b * y) * (1.0 + 0.1 * i) for i, c in enumerate(COLUMNS)}


def test_fit_recovers_a_linear_models_parameters_and_its_profile_matches_the_standard_error():
    truth = {"channel_coefficient": 0.4, "shear_coefficient": 1.5}
    targets = _targets(_linear, truth, COVARIATES, np.random.default_rng(1))
    fit = fit_level("whole", targets, {}, list(truth), {"channel_coefficient": 1.0, "shear_coefficient": 1.0},
                    model=_linear, progress=False)
    for name, value in truth.items():
        se = fit.standard_errors[name]
        assert abs(fit.estimates[name] - value) < 4.0 * se
        # a linear model's chi^2 profile is a parabola: its 95 % interval is estimate +- 1.96 standard errors
        prof = fit.profiles[name]
        assert prof["upper"] - fit.estimates[name] == pytest.approx(1.96 * se, rel=0.1)
        assert fit.estimates[name] - prof["lower"] == pytest.approx(1.96 * se, rel=0.1)
    assert fit.discrepancy == 0.0
    assert fit.gate["passed"], fit.gate


def test_worker_processes_give_the_same_fit_as_one():
    """fit_level with a pool of two spawned workers (analysis.calibration.fit.worker_pool) runs each evaluation's
    targets side by side: the estimates, standard errors and evaluations are those of the serial fit, bit for bit
    (the same model runs, only elsewhere); fewer than one worker is refused."""
    from analysis.calibration.fit import worker_pool

    truth = {"channel_coefficient": 0.4, "shear_coefficient": 1.5}
    targets = _targets(_linear, truth, COVARIATES, np.random.default_rng(1))
    start = {"channel_coefficient": 1.0, "shear_coefficient": 1.0}
    serial = fit_level("whole", targets, {}, list(truth), start, model=_linear, progress=False, profile=False)
    pool = worker_pool(2)
    try:
        pooled = fit_level("whole", targets, {}, list(truth), start, model=_linear, progress=False, profile=False,
                           pool=pool)
    finally:
        pool.shutdown()
    assert pooled.estimates == serial.estimates and pooled.standard_errors == serial.standard_errors
    assert pooled.evaluations == serial.evaluations and pooled.errors == serial.errors
    assert worker_pool(1) is None
    with pytest.raises(ValueError, match="workers 0: allowed an integer >= 1"):
        worker_pool(0)


def _band_linear(name, values):
    return _linear(Target(name, (0, 1), True, {}, {}), None, values, None)


def test_a_band_from_worker_processes_is_the_serial_band():
    """analysis.calibration.bands.band with a pool: the same draws, the same discrepancy factors in the same order,
    so the same quantiles as the serial band."""
    import functools

    from analysis.calibration.bands import band
    from analysis.calibration.fit import worker_pool

    rng = np.random.default_rng(3)
    draws = [{"channel_coefficient": 0.4 + 0.05 * rng.normal(), "shear_coefficient": 1.5 + 0.1 * rng.normal()}
             for _ in range(12)]
    model = functools.partial(_band_linear, "r2")
    serial = band(model, draws, delta=0.1, seed=1)
    pool = worker_pool(2)
    try:
        pooled = band(model, draws, delta=0.1, seed=1, pool=pool)
    finally:
        pool.shutdown()
    assert serial.keys() == pooled.keys()
    for column in serial:
        np.testing.assert_array_equal(serial[column], pooled[column])


def _product(target, case_file, values, fixed):
    x, _ = COVARIATES[target.name]
    a, b = values["channel_coefficient"], values["shear_coefficient"]
    return {c: a * b * x * (1.0 + 0.1 * i) for i, c in enumerate(COLUMNS)}


def test_gate_fails_when_the_data_determine_only_a_product():
    truth = {"channel_coefficient": 0.4, "shear_coefficient": 1.5}
    targets = _targets(_product, truth, COVARIATES, np.random.default_rng(2))
    fit = fit_level("whole", targets, {}, list(truth), {"channel_coefficient": 1.0, "shear_coefficient": 1.0},
                    model=_product, progress=False)
    assert fit.estimates["channel_coefficient"] * fit.estimates["shear_coefficient"] == pytest.approx(0.6, rel=0.02)
    assert not fit.gate["passed"]
    assert any("correlation" in r for r in fit.gate["reasons"]), fit.gate


def _biased(target, case_file, values, fixed):
    """The linear model but 20 % off on one column whatever the parameters: a structural misfit."""
    out = _linear(target, case_file, values, fixed)
    out["settling_flux"] *= 1.2
    return out


def test_discrepancy_brings_chi2_to_its_degrees_of_freedom_when_the_model_misfits():
    truth = {"channel_coefficient": 0.4, "shear_coefficient": 1.5}
    targets = _targets(_linear, truth, COVARIATES, np.random.default_rng(3))
    fit = fit_level("whole", targets, {}, list(truth), {"channel_coefficient": 1.0, "shear_coefficient": 1.0},
                    model=_biased, progress=False, profile=False)
    m, p = 4 * len(COLUMNS), 2
    assert fit.discrepancy > 0.01
    assert fit.chi2 == pytest.approx(m - p, rel=0.1)


def test_registry_names_holdouts_that_no_fit_may_use(tmp_path):
    registry = load_registry()
    assert "deep" in registry.holdouts and all(registry.why[h] for h in registry.holdouts)
    with pytest.raises(RegistryError, match="deep is a pre-registered hold-out"):
        refuse_holdouts(["demo", "deep"], registry)
    refuse_holdouts(["demo", "simple"], registry)  # fine
    bad = tmp_path / "holdouts.toml"
    bad.write_text('[holdouts]\nruns = ["deep"]\n[levels]\nwhole = ["demo", "deep"]\n[holdouts.why]\ndeep = "x"\n')
    with pytest.raises(RegistryError, match=r"\[levels\] whole: deep"):
        load_registry(bad)
    bad.write_text('[holdouts]\nruns = ["deep"]\n')
    with pytest.raises(RegistryError, match="no reason for deep"):
        load_registry(bad)


def _hierarchy(fit):
    from analysis.calibration.hierarchy import Hierarchy

    collision = {"efficiency": 3.3, "standard_error": 0.07, "quadrature_error": 0.006, "merges": 2542,
                 "expected_collisions": 770.0}
    return Hierarchy(collision=collision, levels=[fit], values={}, radius_factor={"value": 4.2, "core_fraction": 0.057,
                                                                                  "runs": ["demo_no_coalescence"]},
                     holdout_errors=None, gate_passed=False, missing={"whole": ["deep_w002"]})


def test_layer_records_the_levels_without_machine_paths_and_bands_read_its_covariance(tmp_path, monkeypatch):
    """The layer of a hierarchy: valid TOML whose numbers carry source tags, no machine folder, and the
    covariance a band is drawn from: the collision level's variance and the fitted level's SE x corr x SE."""
    import tomllib

    from analysis.calibration.bands import covariance_from_layer
    from analysis.calibration.layer import write_layer

    truth = {"channel_coefficient": 0.4, "shear_coefficient": 1.5}
    targets = _targets(_linear, truth, COVARIATES, np.random.default_rng(1))
    fit = fit_level("whole", targets, {}, list(truth), {"channel_coefficient": 1.0, "shear_coefficient": 1.0},
                    model=_linear, progress=False)
    monkeypatch.chdir(tmp_path)
    registry = tmp_path / "data" / "holdouts.toml"
    path = write_layer(_hierarchy(fit), tmp_path / "layer.toml", registry, "settler calibrate --set x")
    text = path.read_text()
    assert str(tmp_path) not in text and "/work" not in text
    within = sum(abs(e) <= 0.10 for errors in fit.errors.values() for e in errors.values())
    assert f"# Targets: {within} of {4 * len(COVARIATES)} fitted window means within 10 %." in text
    layer = tomllib.loads(text)
    assert layer["provenance"]["registry"] == "data/holdouts.toml" and layer["provenance"]["gate_passed"] is False
    assert layer["popbal"]["shear_coefficient"] == pytest.approx(fit.estimates["shear_coefficient"])
    estimates, covariance, keys, delta = covariance_from_layer(path)
    assert keys == ["collision_efficiency", "channel_coefficient", "shear_coefficient"]
    assert covariance[0, 0] == pytest.approx(0.07**2)
    se = [fit.standard_errors[k] for k in keys[1:]]
    assert covariance[1, 2] == pytest.approx(fit.correlation[0, 1] * se[0] * se[1], rel=1e-3)
    assert covariance[0, 1] == 0.0 and delta == fit.discrepancy
    assert "busy_partners" not in layer["popbal"]
    # the 'busy' closure set writes its switch into the layer, so case.calibration=NAME applies what was fitted
    busy = _hierarchy(fit)
    busy.closures = "busy"
    layer = tomllib.loads(write_layer(busy, tmp_path / "busy.toml", registry, "settler calibrate --set x").read_text())
    assert layer["popbal"]["busy_partners"] is True and layer["provenance"]["closures"] == "busy"


def test_holdouts_scored_without_bands_are_summarised_and_written(tmp_path, monkeypatch):
    """--band-samples 0: the hold-outs' errors without bands. The summary says so, the layer records the errors
    and no coverage, and it stays valid TOML."""
    import dataclasses
    import tomllib

    from analysis.calibration.layer import write_layer

    truth = {"channel_coefficient": 0.4, "shear_coefficient": 1.5}
    targets = _targets(_linear, truth, COVARIATES, np.random.default_rng(1))
    fit = fit_level("whole", targets, {}, list(truth), {"channel_coefficient": 1.0, "shear_coefficient": 1.0},
                    model=_linear, progress=False, profile=False)
    errors = {"deep": dict.fromkeys(TARGET_COLUMNS, 0.5)}
    result = dataclasses.replace(_hierarchy(fit), holdout_errors=errors, gate_passed=True, coverage=None)
    assert "no prediction bands (--band-samples 0)" in result.summary()
    monkeypatch.chdir(tmp_path)
    layer = tomllib.loads(write_layer(result, tmp_path / "layer.toml", tmp_path / "h.toml").read_text())
    assert layer["provenance"]["holdouts"]["error_deep"] == [0.5] * len(TARGET_COLUMNS)
    assert "band_coverage" not in layer["provenance"]["holdouts"]


def test_band_of_a_linear_prediction_matches_its_analytic_spread_and_covers_ninety_percent():
    """y = a x1 + b x2 with (a, b) ~ N(m, C): the 90 % band is y_mean +- 1.645 sqrt(g C g) (g = (x1, x2)); of
    400 draws of y from that distribution, 90 % +- 4 % lie inside the band (binomial sd 1.5 %)."""
    from analysis.calibration.bands import band, coverage, parameter_samples

    mean = {"channel_coefficient": 0.4, "shear_coefficient": 1.5}
    covariance = np.array([[0.01**2, -0.5 * 0.01 * 0.03], [-0.5 * 0.01 * 0.03, 0.03**2]])
    keys = list(mean)
    g = np.array([2.0, 1.0])
    samples = parameter_samples(mean, covariance, keys, 4000, seed=3)
    bands = band(lambda v: {"y": g[0] * v["channel_coefficient"] + g[1] * v["shear_coefficient"]}, samples)
    centre, spread = g @ np.array([0.4, 1.5]), math.sqrt(g @ covariance @ g)
    assert bands["y"][0] == pytest.approx(centre - 1.645 * spread, abs=0.05 * spread)
    assert bands["y"][2] == pytest.approx(centre + 1.645 * spread, abs=0.05 * spread)
    draws = np.random.default_rng(9).normal(centre, spread, 400)
    result = coverage({f"r{i}": {"y": bands["y"]} for i in range(400)}, {f"r{i}": {"y": v} for i, v in enumerate(draws)})
    assert result["share"] == pytest.approx(0.9, abs=0.04)


def test_discrepancy_is_a_log_normal_factor_with_the_stated_quantiles():
    """A model output y = 2 with no parameter spread and discrepancy delta: the band is 2 exp(+-1.645 delta), the
    quantiles of a log-normal factor, within 4 standard errors of a sample quantile (40 000 draws: the 5 % quantile
    of z has standard error sqrt(0.05 0.95 / n) / phi(1.645) = 0.0106, so 4.3 % of delta in relative terms); and it
    stays positive even at delta = 1, where 1 + delta z would go below zero for 5 % of the draws."""
    from analysis.calibration.bands import band

    samples = [{}] * 40000
    for delta in (0.3, 1.0):
        q = band(lambda v: {"y": 2.0}, samples, delta=delta, seed=5)["y"]
        assert q[0] == pytest.approx(2.0 * math.exp(-1.645 * delta), rel=0.043 * delta)
        assert q[2] == pytest.approx(2.0 * math.exp(1.645 * delta), rel=0.043 * delta)
        assert q[0] > 0.0


def test_settler_calibrate_set_refuses_a_registry_that_fits_a_holdout(tmp_path):
    import subprocess
    import sys

    bad = tmp_path / "holdouts.toml"
    bad.write_text('[holdouts]\nruns = ["deep"]\n[holdouts.why]\ndeep = "x"\n[levels]\nwhole = ["deep"]\n')
    done = subprocess.run([sys.executable, "-m", "settler", "calibrate", "--set", str(bad)], capture_output=True,
                          text=True)
    assert done.returncode == 2
    assert "deep is a pre-registered hold-out" in done.stderr and "Traceback" not in done.stderr


def test_leaving_a_family_out_holds_its_runs_out_of_every_level():
    """Leave-one-family-out: the family's runs join the pre-registered hold-outs (with a reason) and leave every
    level; the pre-registered ones stay; an unknown family is refused naming the allowed ones."""
    from analysis.calibration.registry import leave_family_out

    registry = load_registry()
    left = leave_family_out(registry, "width")
    assert left.holdouts == (*registry.holdouts, *registry.families["width"])
    assert left.left_out == registry.families["width"] and registry.left_out == ()
    for level, runs in left.levels.items():
        assert not set(runs) & set(registry.families["width"]), level
        assert set(runs) == set(registry.levels[level]) - set(registry.families["width"])
    assert all(left.why[r] for r in left.holdouts)
    assert "deep_w005_no_coalescence" not in left.levels["transport"]  # the family's coalescence-off variant too
    refuse_holdouts(left.levels["whole"], left)  # what is left may be fitted
    import dataclasses

    lone = dataclasses.replace(registry, families={**registry.families, "all": registry.levels["transport"]})
    with pytest.raises(RegistryError, match="takes every run of level transport"):
        leave_family_out(lone, "all")
    with pytest.raises(RegistryError, match="--leave-out 'nope': .*allowed: feed, property, width"):
        leave_family_out(registry, "nope")


@pytest.mark.parametrize("extra, message", [(["--leave-out", "feed", "--write", "x.toml"], "not a calibration layer"),
                                            (["--training-only", "--write", "x.toml"], "not a calibration layer"),
                                            (["--no-profile"], "--no-profile without --training-only"),
                                            (["--band-samples", "3"], "--band-samples 3: allowed 0"),
                                            (["--leave-out", "nope"], "--leave-out 'nope': holdouts.toml has no")])
def test_settler_calibrate_set_refuses_bad_cross_validation_options(extra, message):
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "settler", "calibrate", "--set", "data/calibration/holdouts.toml",
                           *extra], capture_output=True, text=True)
    assert done.returncode == 2 and message in done.stderr and "Traceback" not in done.stderr, done.stderr


def test_settler_calibrate_names_a_closure_the_fold_cannot_measure(monkeypatch):
    """A fold that leaves out the only runs a measured closure rests on (zones_stir without the paper family: the
    spread core's share, its collision radius and the stirring come from simple and cubic alone) is refused by name
    as bad input, not reported as an internal error; the measure itself is stubbed here."""
    import argparse

    import analysis.calibration.command as command
    from analysis.calibrate import add_arguments
    from analysis.calibration.zones import MeasureError
    from settler.output import OutputError

    def refuse(*args, **kwargs):
        raise MeasureError("no run of demo_cell_25, deep_w002 is spread by the regime rule")

    monkeypatch.setattr(command, "calibrate_set", refuse)
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--set", "data/calibration/holdouts.toml", "--leave-out", "paper", "--training-only",
                              "--no-profile", "--closures", "zones_stir"])
    with pytest.raises(OutputError, match="--closures zones_stir with family 'paper' left out: no run of "
                                          "demo_cell_25, deep_w002 is spread .*allowed: a closure set or fold"):
        command.run_set(args)


@pytest.mark.parametrize("measure", ["spread_share", "dispersion", "floor"])
def test_a_closure_no_run_carries_raises_measure_error(measure):
    """The measures a fold can be left without raise MeasureError (what settler calibrate refuses by name) when no
    run given carries them, not a bare ValueError (reported as an internal error)."""
    from analysis.calibration.zones import MeasureError, dispersion_from_suspension, spread_share_from_groups
    from analysis.floor_layer import bottom_factor

    call = {"spread_share": lambda: spread_share_from_groups([], "data/reference", {}),
            "dispersion": lambda: dispersion_from_suspension([], "data/reference"),
            "floor": lambda: bottom_factor([], "data/reference")}[measure]
    with pytest.raises(MeasureError):
        call()


def test_settler_calibrate_fold_passes_no_profile_and_records_what_it_scored(tmp_path, monkeypatch):
    """--no-profile reaches the hierarchy as profile=False, and hierarchy.json's 'scored' lists the runs a fold
    scored (its left-out family), not the registry's hold-outs; the hierarchy itself is stubbed here."""
    import argparse
    import json

    import analysis.calibration.command as command
    from analysis.calibrate import add_arguments
    from analysis.calibration.hierarchy import Hierarchy

    seen = {}

    def fake(registry, reference_dir, **kwargs):
        seen.update(kwargs, left_out=registry.left_out)
        errors = {r: dict.fromkeys(("droplet_count", "mean_diameter", "settling_flux", "channel_velocity"), 0.01)
                  for r in registry.left_out}
        return Hierarchy(collision={"efficiency": 0.8, "standard_error": 0.06, "merges": 222,
                                    "expected_collisions": 278.0},
                         levels=[], values={}, radius_factor={"value": 6.6, "core_fraction": 0.02, "runs": ["a"]},
                         holdout_errors=errors, gate_passed=True, training_only=True, left_out=registry.left_out)

    monkeypatch.setattr(command, "calibrate_set", fake)
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--set", "data/calibration/holdouts.toml", "--leave-out", "feed", "--training-only",
                              "--no-profile", "--quiet", "--out", str(tmp_path / "fold")])
    assert command.run_set(args) == 0
    assert seen["profile"] is False and seen["training_only"] is True
    written = json.loads((tmp_path / "fold" / "hierarchy.json").read_text())
    assert written["scored"] == ["demo_feed_half_fine", "demo_feed_double_fine"] and written["profile"] is False
    assert "deep_w003_fine" in written["holdouts"] and "deep_w003_fine" not in written["scored"]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["designed", "zones_core"])
def test_settler_calibrate_reproduces_the_stored_layer_from_its_recorded_command(tmp_path, name):
    """Each committed hierarchical layer (data/calibration/<name>.toml) comes back from the command in its
    [provenance], run on a clean checkout of its recorded code commit (the reference runs of that commit: a run
    stored later, such as a new seed pair, changes the weights): the same [popbal] values to 1e-9 (popbal and the
    fit are deterministic, serial or in worker processes), and a provenance that names no machine folder. About 40
    minutes (designed) and two hours (zones_core) on two cores."""
    import os
    import shlex
    import subprocess
    import sys
    import tomllib
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    stored_path = root / "data" / "calibration" / f"{name}.toml"
    if not stored_path.is_file() or not (root / ".git").exists():
        pytest.skip(f"needs data/calibration/{name}.toml in a git checkout")
    stored = tomllib.loads(stored_path.read_text())
    provenance = stored["provenance"]
    assert provenance["code_tree_dirty"] is False
    command = shlex.split(provenance["command"])
    assert command[:2] == ["settler", "calibrate"] and "/work" not in provenance["command"]
    checkout = tmp_path / "checkout"
    subprocess.run(["git", "-C", str(root), "worktree", "add", "--detach", str(checkout), provenance["code_commit"]],
                   check=True, capture_output=True)
    try:
        args = list(command[2:])
        for option in ("--write", "--out"):
            if option in args:
                i = args.index(option)
                del args[i:i + 2]
        layer = tmp_path / "again.toml"
        env = {**os.environ, "PYTHONPATH": str(checkout)}
        done = subprocess.run([sys.executable, "-m", "settler", "calibrate", *args, "--write", str(layer)],
                              cwd=checkout, env=env, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr[-2000:]
        again = tomllib.loads(layer.read_text())
        for key, value in stored["popbal"].items():
            assert again["popbal"][key] == (pytest.approx(value, rel=1e-9) if isinstance(value, float) else value), key
    finally:
        subprocess.run(["git", "-C", str(root), "worktree", "remove", "--force", str(checkout)], capture_output=True)


def test_a_run_is_scored_under_the_fitted_closures_alone_as_the_written_layer_is_applied():
    """simple's resolved case.toml carries the paper layer's keys (plume_reynolds_scale among them); the calibration
    scores it with those keys gone, exactly as `case.calibration=designed` applies the written layer."""
    import tomllib
    from pathlib import Path

    import popbal
    from analysis.calibration.fit import reduced_means
    from settler.cases import load_case

    root = Path(__file__).resolve().parents[1]
    case_file = root / "data" / "reference" / "simple" / "case.toml"
    assert load_case(case_file).popbal.plume_reynolds_scale is not None  # the paper layer's key is in the file
    layer = tomllib.loads((root / "data" / "calibration" / "designed.toml").read_text())["popbal"]
    target = Target(name="simple", window=(2.0, 4.0), steady=True, means={}, standard_errors={})
    fixed = {f"popbal.{k}": v for k, v in layer.items()}
    scored = reduced_means(target, case_file, {}, fixed)
    applied = load_case(case_file, {"case.calibration": "designed", "popbal.end_time": 4.0,
                                    "popbal.output_interval": 0.5})
    assert applied.popbal.plume_reynolds_scale is None
    expected = window_means(popbal.run(popbal.setup(applied), progress=False).timeseries, (2.0, 4.0))
    assert scored == expected


def _roof_reference(tmp_path, name="cubic"):
    """A copy of a stored reference's files that roof_from_zones and dilution_from_zones read."""
    import shutil

    folder = tmp_path / name
    folder.mkdir()
    for f in ("timeseries.csv", "zones.csv", "zone_profile.csv", "channel_profile.csv", "case.toml", "reference.json"):
        shutil.copy(f"data/reference/{name}/{f}", folder / f)
    return folder


def test_dilution_fit_recovers_the_law_and_its_scatter():
    """phi = k_R^-2 / (1 + Re / Re_d): exact data give k_R and Re_d back to round-off; 10 % log-normal scatter on
    twelve runs gives them within three of the fit's own standard errors, which shrink as 1 / sqrt(n)."""
    from analysis.calibration.zones import fit_dilution

    reynolds = np.geomspace(0.3, 20.0, 12)
    phi = 1.0 / (4.9**2 * (1.0 + reynolds / 2.4))
    exact = fit_dilution(phi, reynolds)
    assert exact["value"] == pytest.approx(4.9, rel=1e-8) and exact["reynolds"] == pytest.approx(2.4, rel=1e-8)
    rng = np.random.default_rng(3)
    noisy = fit_dilution(phi * np.exp(0.1 * rng.standard_normal(12)), reynolds)
    se = noisy["standard_errors"]
    assert abs(noisy["value"] - 4.9) < 3.0 * se["channel_radius_factor"]
    assert abs(noisy["reynolds"] - 2.4) < 3.0 * se["plume_dilution_reynolds"]
    assert 0.05 < noisy["rms"] < 0.15 and -1.0 < noisy["correlation"] < 0.0  # a larger phi0 asks a smaller Re_d
    more = fit_dilution(np.tile(phi, 4) * np.exp(0.1 * rng.standard_normal(48)), np.tile(reynolds, 4))
    assert more["standard_errors"]["plume_dilution_reynolds"] < 0.7 * se["plume_dilution_reynolds"]


def test_dilution_from_zones_reads_the_core_fraction_and_axis_velocity_of_each_run(tmp_path):
    """Per run, phi_p is radius_factor_from_zones' core volume fraction, and Re = rho_s u R / mu with R = sqrt(Q /
    (pi phi_p u)) from the axis velocity of channel_profile.csv over the same band and window; a run whose R
    exceeds its inlet radius is left out with the reason."""
    from analysis.calibration.zones import CORE_BAND, dilution_from_zones, radius_factor_from_zones
    from analysis.steady import window_of as steady_window_of
    from settler.cases import load_case

    import shutil

    folder = _roof_reference(tmp_path)
    copies = ["cubic", "cubic_2", "cubic_3"]  # three runs: the least a fit of two parameters takes
    for name in copies[1:]:
        shutil.copytree(folder, tmp_path / name)
    got = dilution_from_zones(copies, tmp_path)
    case = load_case(folder / "case.toml")
    series = pd.read_csv(folder / "timeseries.csv", comment="#")
    (start, _), _ = steady_window_of(series)
    profile = pd.read_csv(folder / "channel_profile.csv", comment="#")
    height = profile.z.max() + profile.z.min()
    rows = profile[(profile.time > start) & (profile.z >= CORE_BAND[0] * height)
                   & (profile.z <= CORE_BAND[1] * height)]
    u = rows.channel_velocity.mean()
    phi = radius_factor_from_zones(["cubic"], tmp_path)["core_fraction"]
    radius = math.sqrt(case.feed.mass_rate / case.matte.density / (math.pi * phi * u))
    assert got["per_run"]["cubic"] == pytest.approx((phi, case.slag.density * u * radius / case.slag_viscosity),
                                                    rel=1e-9)
    narrow = load_case(folder / "case.toml")  # the same run fed through an inlet narrower than its plume
    text = (folder / "case.toml").read_text().replace(f"inlet_diameter = {narrow.geometry.inlet_diameter!r}",
                                                      f"inlet_diameter = {1.5 * radius!r}")
    (folder / "case.toml").write_text(text)
    with pytest.raises(ValueError, match=r"at least 3 runs .*got cubic_2, cubic_3 \(left out: \{'cubic': 'R .* mm over "
                                         r"the inlet radius"):
        dilution_from_zones(copies, tmp_path)


def test_roof_coefficient_from_zones_counts_the_slag_that_flows_through_the_roof(tmp_path):
    """The layers closures' c_L from cubic's zone diagnostics: j = phi (c_L phi drho g delta^2 / mu + w) with the
    slag feed's velocity w through the inlet disk (fulldem's velocity inlet), recomputed here from the files; and a
    roof the slag alone would carry is refused with the run named, not averaged in as NaN."""
    from analysis.calibration.zones import roof_from_zones
    from analysis.steady import window_of as steady_window_of
    from settler.cases import load_case
    from settler.physics import STANDARD_GRAVITY

    folder = _roof_reference(tmp_path)
    got = roof_from_zones(["cubic"], tmp_path)
    case = load_case(folder / "case.toml")
    series = pd.read_csv(folder / "timeseries.csv", comment="#")
    (start, end), _ = steady_window_of(series)
    zones = pd.read_csv(folder / "zones.csv", comment="#")
    rows = zones[(zones.time >= start) & (zones.time <= end)]
    thickness = rows.roof_thickness.mean()
    phi = (rows.roof_thickness * rows.roof_volume_fraction.fillna(0.0)).mean() / thickness
    inlet = math.pi * (0.5 * case.geometry.inlet_diameter) ** 2
    j = case.feed.mass_rate / case.matte.density / inlet
    w = case.slag.feed_rate / case.slag.density / inlet
    drho = case.matte.density - case.slag.density
    c_l = (j / phi - w) * case.slag_viscosity / (phi * drho * STANDARD_GRAVITY * thickness**2)
    assert got["per_run"]["cubic"] == pytest.approx(c_l, rel=1e-9)
    assert got["thickness"] == pytest.approx(thickness, rel=1e-12)
    without_slag = j * case.slag_viscosity / (drho * STANDARD_GRAVITY * (phi * thickness) ** 2)
    assert without_slag / got["per_run"]["cubic"] > 1.1  # the slag term matters in cubic (0.043 against 0.036)

    # the drainage law's k = j / (phi_L U_s) only where the cells resolve the roof: not at cubic's 5 mm cells
    assert got["drainage_per_run"] == {} and math.isnan(got["drainage_ratio"])
    text = (folder / "case.toml").read_text()
    (folder / "case.toml").write_text(text.replace(f"cell_size = {case.fulldem.cell_size!r}", "cell_size = 0.0025"))
    u_s = drho * STANDARD_GRAVITY * case.feed.mean_diameter**2 / (18.0 * case.slag_viscosity)
    resolved = roof_from_zones(["cubic"], tmp_path)
    assert resolved["drainage_ratio"] == pytest.approx(j / (phi * u_s), rel=1e-9)
    assert resolved["drainage_per_run"] == {"cubic": resolved["drainage_ratio"]}
    (folder / "case.toml").write_text(text)

    # a roof so full that the slag alone would carry twice the feed through it: no c_L to measure
    zones.loc[:, "roof_volume_fraction"] *= 2.0 * j / (w * phi)
    zones.to_csv(folder / "zones.csv", index=False)
    with pytest.raises(ValueError, match="carried by the slag feed alone"):
        roof_from_zones(["cubic"], tmp_path)


def test_cell_efficiency_is_the_kernel_runs_merges_over_its_cell_by_cell_collisions(tmp_path):
    """The 'zones_dilution' collision level: all bands' merges over all bands' cell-by-cell collisions, with the
    Poisson count of the merges and the rate's scatter in quadrature (E sqrt(1/M + s^2)), from a stand-in table;
    every closure set that asks for it takes it, the others the kernel run's slices."""
    from analysis.band_efficiency import COLLISIONS_FILE, COLLISIONS_UNITS
    from analysis.calibration.hierarchy import CLOSURES, cell_efficiency
    from settler.output import units_line

    rows = pd.DataFrame({column: [0.0, 0.0] for column in COLLISIONS_UNITS})
    rows["z"] = [0.025, 0.075]
    rows["merges_under_inlet"], rows["merges_elsewhere"], rows["collisions"] = [60.0, 30.0], [6.0, 4.0], [110.0, 15.0]
    rows["gravitational_under_inlet"], rows["gravitational_elsewhere"] = [100.0, 10.0], [10.0, 5.0]
    rows["shear_under_inlet"], rows["shear_elsewhere"] = [8.0, 3.0], [1.0, 2.0]
    header = (units_line(COLLISIONS_UNITS)
              + "# window: 10.0 20.0 s; cell: 0.005 m; rate_scatter: 0.05; snapshots: 10.0 20.0\n")
    (tmp_path / COLLISIONS_FILE).write_text(header + rows.to_csv(index=False))
    got = cell_efficiency(tmp_path)
    assert got["efficiency"] == pytest.approx(100.0 / 125.0, rel=1e-12)
    assert got["standard_error"] == pytest.approx(0.8 * math.sqrt(1.0 / 100.0 + 0.05**2), rel=1e-12)
    assert got["merges"] == 100 and got["expected_collisions"] == 125.0 and got["form"] == "cell"
    assert [name for name, c in CLOSURES.items() if c.get("cell_efficiency")] == ["zones_dilution", "zones_floor",
                                                                                    "zones_line", "zones_drain",
                                                                                    "zones_core", "zones_stir",
                                                                                    "zones_scale"]


def test_roof_kernel_from_the_collisions_by_height_of_two_runs(tmp_path):
    """The 'zones' closures' roof kernel, by hand from two stand-in runs (the demo's case, no slag feed): each a top
    band under the inlet (merges M, well-mixed collisions C_g + C_s, shear rate G, matte V_b) and a roof in zones.csv
    (thickness delta, volume fraction phi over the window; rows outside it ignored). The layer holds f = I A / V_b of
    the band's matte (I = delta phi, A the inlet disk), so its collisions mixed over A delta are (C_g + C_s) f^2 h_b /
    delta and E_L = M over them; its drainage velocity is u_L = j delta / I (j the matte fed over A), and the shear
    coefficient G delta / u_L; each the geometric mean of the runs. A table without the well-mixed shear columns and
    an empty list of runs are refused. The layer written for 'zones' carries both, and the confinement switch with
    its own note."""
    import shutil
    import tomllib
    from pathlib import Path

    from analysis.band_efficiency import COLLISIONS_FILE, COLLISIONS_UNITS
    from analysis.calibration.zones import roof_kernel_from_collisions
    from settler.cases import load_case
    from settler.output import units_line

    root = Path(__file__).resolve().parents[1]
    case = load_case(root / "data" / "reference" / "demo" / "case.toml")
    assert case.slag.feed_rate == 0.0
    area = math.pi * (0.5 * case.geometry.inlet_diameter) ** 2
    j = case.feed.mass_rate / case.matte.density / area  # matte fed over the inlet disk [m/s]
    h_b = case.geometry.height / 2  # two bands in the stand-in tables
    # M, C_g, C_s, G [1/s], V_b [m^3], delta [m], phi [-]
    given = {"a": (900.0, 300.0, 200.0, 1.5, 2.0e-5, 0.005, 0.3), "b": (400.0, 100.0, 60.0, 0.8, 1.0e-5, 0.008, 0.1)}
    for name, (merges, gravitational, shear, rate, volume, delta, phi) in given.items():
        folder = tmp_path / name
        folder.mkdir()
        shutil.copy(root / "data" / "reference" / "demo" / "case.toml", folder / "case.toml")
        rows = pd.DataFrame({column: [1.0, 1.0] for column in COLLISIONS_UNITS})
        rows["z"] = [0.025, 0.075]  # the second row is the top band
        rows.loc[1, ["merges_under_inlet", "mixed_under_inlet", "mixed_shear_under_inlet", "shear_rate_under_inlet",
                     "volume_under_inlet"]] = [merges, gravitational, shear, rate, volume]
        header = (units_line(COLLISIONS_UNITS)
                  + "# window: 10.0 20.0 s; cell: 0.005 m; rate_scatter: 0.01; snapshots: 10.0 20.0\n")
        (folder / COLLISIONS_FILE).write_text(header + rows.to_csv(index=False))
        pd.DataFrame({"time": [5.0, 10.0, 15.0, 20.0], "roof_thickness": [0.02, delta, delta, delta],
                      "roof_volume_fraction": [0.9, phi, phi, phi], "roof_peak_fraction": 0.0, "rising_count": 0.0,
                      "rising_volume": 0.0}).to_csv(folder / "zones.csv", index=False)
    got = roof_kernel_from_collisions(["a", "b"], tmp_path)
    e, c = {}, {}
    for name, (merges, gravitational, shear, rate, volume, delta, phi) in given.items():
        share = min(delta * phi * area / volume, 1.0)
        e[name] = merges / ((gravitational + shear) * share**2 * h_b / delta)
        c[name] = rate * delta / (j * delta / (delta * phi))
        assert got["per_run"][name]["share"] == pytest.approx(share, rel=1e-12) and 0.3 < share < 0.4
    assert got["per_run"]["a"]["efficiency"] == pytest.approx(e["a"], rel=1e-12)
    assert got["efficiency"] == pytest.approx(math.sqrt(e["a"] * e["b"]), rel=1e-12)
    assert got["shear_coefficient"] == pytest.approx(math.sqrt(c["a"] * c["b"]), rel=1e-12)
    # at popbal's thickness delta_p instead of each run's own: collisions x delta / delta_p, u_L = j delta_p / I
    fixed = roof_kernel_from_collisions(["a"], tmp_path, thickness=0.01)
    merges, gravitational, shear, rate, volume, delta, phi = given["a"]
    share = delta * phi * area / volume
    assert fixed["efficiency"] == pytest.approx(merges / ((gravitational + shear) * share**2 * h_b / 0.01), rel=1e-12)
    assert fixed["shear_coefficient"] == pytest.approx(rate * 0.01 / (j * 0.01 / (delta * phi)), rel=1e-12)
    # with popbal's hindered relative velocities: C_g x (1 - phi_L)^n at phi_L = I / delta_p, the shear part as it was
    hindered = roof_kernel_from_collisions(["a"], tmp_path, thickness=0.01, hindered_exponent=4.65)
    h = (1.0 - delta * phi / 0.01) ** 4.65
    assert hindered["per_run"]["a"]["hindrance"] == pytest.approx(h, rel=1e-12) and 0.4 < h < 0.6
    assert hindered["efficiency"] == pytest.approx(merges / ((h * gravitational + shear) * share**2 * h_b / 0.01),
                                                   rel=1e-12)
    assert hindered["shear_coefficient"] == fixed["shear_coefficient"]

    old = pd.read_csv(tmp_path / "b" / COLLISIONS_FILE, comment="#").drop(columns=["mixed_shear_under_inlet"])
    text = (tmp_path / "b" / COLLISIONS_FILE).read_text().splitlines(keepends=True)
    (tmp_path / "b" / COLLISIONS_FILE).write_text("".join(text[:2]) + old.to_csv(index=False))
    with pytest.raises(FileNotFoundError, match="b/collisions_by_height.csv: no well-mixed shear"):
        roof_kernel_from_collisions(["a", "b"], tmp_path)
    with pytest.raises(ValueError, match="needs at least one run"):
        roof_kernel_from_collisions([], tmp_path)

    from analysis.calibration.layer import write_layer

    truth = {"channel_coefficient": 0.4, "shear_coefficient": 1.5}
    targets = _targets(_linear, truth, COVARIATES, np.random.default_rng(1))
    fit = fit_level("whole", targets, {}, list(truth), {"channel_coefficient": 1.0, "shear_coefficient": 1.0},
                    model=_linear, progress=False)
    zones = _hierarchy(fit)
    zones.closures = "zones"
    zones.roof = {"coefficient": 0.034, "thickness": 0.01, "per_run": {"a": 0.034}, "runs": ["a"], "kernel": got}
    layer = tomllib.loads(write_layer(zones, tmp_path / "zones.toml", tmp_path / "holdouts.toml", "x").read_text())
    assert layer["popbal"]["roof_collision_efficiency"] == pytest.approx(got["efficiency"])
    assert layer["popbal"]["roof_shear_coefficient"] == pytest.approx(got["shear_coefficient"])
    assert layer["popbal"]["confinement"] is True
    assert "confined plume" in (tmp_path / "zones.toml").read_text()


@pytest.mark.parametrize("stored_whole, training_only, left_out, scored",
                         [(("demo",), False, (), False), (("demo", "deep_w002"), False, (), True),
                          (("demo", "deep_w002"), True, (), False), (("demo", "deep_w002"), True, ("demo_x",), True)])
def test_holdouts_are_scored_only_by_a_fit_on_the_whole_registered_set(tmp_path, monkeypatch, stored_whole,
                                                                       training_only, left_out, scored):
    """A hold-out is scored once, by the fit on every run the registry names: while a level's run is not stored
    yet, or when the fit is asked for the training levels alone (--training-only), a fit that passes its gate still
    reads no hold-out, and the summary says why; a cross-validation fold asked for the training levels alone scores
    its left-out family and nothing else, so that the blind hold-outs stay blind. The fits are stubbed here (their
    physics is tested above and in test_calibration.py); this is the rule only."""
    import analysis.calibration.hierarchy as h
    import analysis.kernel_run as kr
    from analysis.calibration.fit import LevelFit
    from analysis.calibration.registry import Registry

    for run in ("kernel", "demo_no_coalescence", *stored_whole, "deep", *left_out):
        (tmp_path / run).mkdir()
        (tmp_path / run / "timeseries.csv").write_text("time\n0\n")
    registry = Registry(holdouts=("deep", "deep_fine", *left_out), why={"deep": "test", "deep_fine": "not stored"},
                        families={}, levels={"collision": ("kernel",), "transport": ("demo_no_coalescence",),
                                             "whole": ("demo", "deep_w002")}, path=tmp_path / "holdouts.toml",
                        left_out=left_out)

    def fit_level(level, targets, case_files, parameters, start, fixed, **kw):
        names = list(parameters)
        return LevelFit(level=level, runs=list(case_files), parameters=names, estimates={n: 1.0 for n in names},
                        standard_errors={n: 0.1 for n in names}, correlation=np.eye(len(names)), discrepancy=0.0,
                        chi2=1.0, residual_count=10, evaluations=3, status="converged", errors={},
                        gate={"passed": True, "reasons": []})

    read = []
    monkeypatch.setattr(kr, "kernel_run_efficiency",
                        lambda folder: {"efficiency": 3.3, "standard_error": 0.07, "merges": 2542,
                                        "expected_collisions": 770.0})
    monkeypatch.setattr(h, "seed_scatter", lambda reference_dir: {})
    monkeypatch.setattr(h, "radius_factor_from_zones", lambda runs, d: {"value": 4.2, "core_fraction": 0.057,
                                                                        "runs": list(runs)})
    monkeypatch.setattr(h, "load_target", lambda run, d, seed: run)
    monkeypatch.setattr(h, "fit_level", fit_level)
    monkeypatch.setattr(h, "_score_holdouts", lambda registry, *a: (read.extend(registry.holdouts) or
                                                                    ({"deep": dict.fromkeys(h.TARGET_COLUMNS, 0.05)}, None)))
    result = h.calibrate_set(registry, tmp_path, progress=False, band_samples=0, training_only=training_only)
    assert result.gate_passed
    assert (result.holdout_errors is not None) is scored
    expected = (list(left_out) if training_only else ["deep", "deep_fine"]) if scored else []
    assert read == expected  # _score_holdouts itself scores the stored ones only
    assert result.missing["holdouts"] == ["deep_fine"]
    assert "hold-outs registered but not stored yet (not scored): deep_fine" in result.summary()
    if left_out:
        assert "left-out family (cross-validation; the pre-registered hold-outs not scored):" in result.summary()
        result.holdout_errors, result.gate_passed = None, False  # as a fold whose gate failed reads
        assert "left-out family: not scored (the identifiability gate did not pass)" in result.summary()
    elif training_only:
        assert "whole" not in result.missing
        assert "hold-outs: not scored (--training-only: the training levels alone)" in result.summary()
    elif not scored:
        assert result.missing["whole"] == ["deep_w002"]
        assert "not scored (runs the registry names are not stored yet" in result.summary()
    else:
        assert "whole" not in result.missing


def test_channel_kernel_from_the_collisions_by_height_of_a_run(tmp_path):
    """The channel's kernel by hand from a stand-in run (the demo's case) of four bands, the floor's and the roof's
    left out: the middle two under the inlet hold merges M, well-mixed collisions C_g + C_s, cell-by-cell C_cell and
    shear rate G (weighted by the droplets held). popbal's channel at the inlet form with factor 0.5 has R_c = half
    the inlet radius, so its section is a quarter of the inlet's and E_ch = M / (4 (C_g + C_s)); u_s is the steady
    plume law sqrt(c_ch Q drho g / (pi mu)) (transport factor 1), the shear coefficient G R_c / u_s; the collision
    radius is the inlet radius times sqrt(C_g / C_cell). A run without merges there is refused by name."""
    import shutil
    from pathlib import Path

    from analysis.band_efficiency import COLLISIONS_FILE, COLLISIONS_UNITS
    from analysis.calibration.zones import channel_kernel_from_collisions
    from settler.cases import load_case
    from settler.output import units_line

    root = Path(__file__).resolve().parents[1]
    folder = tmp_path / "a"
    folder.mkdir()
    shutil.copy(root / "data" / "reference" / "demo" / "case.toml", folder / "case.toml")
    rows = pd.DataFrame({column: [1.0] * 4 for column in COLLISIONS_UNITS})
    rows["z"] = [0.0875, 0.0125, 0.0375, 0.0625]  # unsorted: the first row is the top band, the second the floor's
    rows["merges_under_inlet"] = [1e6, 1e6, 300.0, 500.0]
    rows["mixed_under_inlet"] = [1e6, 1e6, 100.0, 150.0]
    rows["mixed_shear_under_inlet"] = [1e6, 1e6, 40.0, 60.0]
    rows["gravitational_under_inlet"] = [1e6, 1e6, 400.0, 600.0]
    rows["shear_rate_under_inlet"] = [1e3, 1e3, 2.0, 4.0]
    rows["held"] = [1e6, 1e6, 100.0, 300.0]
    header = (units_line(COLLISIONS_UNITS)
              + "# window: 10.0 20.0 s; cell: 0.005 m; rate_scatter: 0.01; snapshots: 10.0 20.0\n")
    (folder / COLLISIONS_FILE).write_text(header + rows.to_csv(index=False))
    values = {"popbal.channel_radius_form": "inlet", "popbal.channel_radius_factor": 0.5,
              "popbal.channel_coefficient": 0.4, "popbal.confinement": False}
    got = channel_kernel_from_collisions(["a"], tmp_path, values)["per_run"]["a"]
    case = load_case(folder / "case.toml")
    inlet_radius = 0.5 * case.geometry.inlet_diameter
    q = case.feed.mass_rate / case.matte.density
    u_s = math.sqrt(0.4 * q * (case.matte.density - case.slag.density) * 9.80665 / (math.pi * case.slag_viscosity))
    assert got["channel_radius"] == pytest.approx(0.5 * inlet_radius, rel=1e-12)
    assert got["plume_velocity"] == pytest.approx(u_s, rel=1e-6)
    assert got["efficiency"] == pytest.approx(800.0 / (4.0 * 350.0), rel=1e-12)
    assert got["shear_rate"] == pytest.approx((2.0 * 100 + 4.0 * 300) / 400, rel=1e-12)
    assert got["shear_coefficient"] == pytest.approx(3.5 * 0.5 * inlet_radius / u_s, rel=1e-6)
    assert got["collision_radius"] == pytest.approx(inlet_radius * math.sqrt(250.0 / 1000.0), rel=1e-12)
    assert got["cell_efficiency"] == pytest.approx(0.8, rel=1e-12)

    rows["merges_under_inlet"] = [1e6, 1e6, 0.0, 0.0]
    (folder / COLLISIONS_FILE).write_text(header + rows.to_csv(index=False))
    with pytest.raises(ValueError, match="a/collisions_by_height.csv: no merges"):
        channel_kernel_from_collisions(["a"], tmp_path, values)


def test_floor_shear_is_the_bottom_bands_slag_shear_over_popbals_plume_turning_over_its_layer(tmp_path):
    """floor_shear_from_collisions: the full run's slag shear rate at the bottom band's droplets (under the inlet and
    elsewhere, weighted by the droplet volume each holds) over popbal's bottom layer's u_s t / h_b. At the inlet form
    with factor 0.5 and bottom_layer_factor 1, h_b = R_c = half the inlet radius and u_s is the steady plume law
    sqrt(c_ch Q drho g / (pi mu)) (transport factor 1). A band without a shear rate, and values without a bottom
    layer, are refused by name."""
    import shutil
    from pathlib import Path

    from analysis.band_efficiency import COLLISIONS_FILE, COLLISIONS_UNITS
    from analysis.calibration.zones import floor_shear_from_collisions
    from settler.cases import load_case
    from settler.output import units_line

    root = Path(__file__).resolve().parents[1]
    folder = tmp_path / "a"
    folder.mkdir()
    shutil.copy(root / "data" / "reference" / "demo" / "case.toml", folder / "case.toml")
    rows = pd.DataFrame({column: [1.0] * 3 for column in COLLISIONS_UNITS})
    rows["z"] = [0.05, 0.0125, 0.0875]  # unsorted: the floor's band is the second row
    rows["shear_rate_under_inlet"] = [1e3, 3.0, 1e3]
    rows["shear_rate_elsewhere"] = [1e3, 0.5, 1e3]
    rows["volume_under_inlet"] = [1.0, 3e-7, 1.0]
    rows["volume_elsewhere"] = [1.0, 1e-7, 1.0]
    header = (units_line(COLLISIONS_UNITS)
              + "# window: 10.0 20.0 s; cell: 0.005 m; rate_scatter: 0.01; snapshots: 10.0 20.0\n")
    (folder / COLLISIONS_FILE).write_text(header + rows.to_csv(index=False))
    values = {"popbal.channel_radius_form": "inlet", "popbal.channel_radius_factor": 0.5,
              "popbal.channel_coefficient": 0.4, "popbal.confinement": False, "popbal.bottom_layer_factor": 1.0}
    got = floor_shear_from_collisions(["a"], tmp_path, values)
    case = load_case(folder / "case.toml")
    q = case.feed.mass_rate / case.matte.density
    u_s = math.sqrt(0.4 * q * (case.matte.density - case.slag.density) * 9.80665 / (math.pi * case.slag_viscosity))
    own = u_s / (0.25 * case.geometry.inlet_diameter)
    rate = (3.0 * 3e-7 + 0.5 * 1e-7) / 4e-7
    assert got["per_run"]["a"]["shear_rate"] == pytest.approx(rate, rel=1e-12)
    assert got["per_run"]["a"]["popbal_shear_rate"] == pytest.approx(own, rel=1e-6)
    assert got["value"] == pytest.approx(rate / own, rel=1e-6)

    with pytest.raises(ValueError, match="no bottom layer in this case"):
        floor_shear_from_collisions(["a"], tmp_path, {k: v for k, v in values.items() if "bottom" not in k})
    rows["shear_rate_under_inlet"] = [1e3, float("nan"), 1e3]
    rows["shear_rate_elsewhere"] = [1e3, float("nan"), 1e3]
    (folder / COLLISIONS_FILE).write_text(header + rows.to_csv(index=False))
    with pytest.raises(ValueError, match="a/collisions_by_height.csv: no slag shear rate at droplets in the bottom"):
        floor_shear_from_collisions(["a"], tmp_path, values)
    with pytest.raises(ValueError, match="at least one stored run"):
        floor_shear_from_collisions([], tmp_path, values)


@pytest.mark.parametrize("closures", ["zones_floor", "zones_line", "zones_drain"])
def test_zones_floor_fits_the_plume_without_a_bottom_layer_and_measures_it_in_the_coalescing_whole_runs(
        tmp_path, monkeypatch, closures):
    """'zones_floor': the coalescence-off transport runs' floors fill, so level 2 fits the channel coefficient alone
    with no bottom layer, and level 3 holds f_b = the geometric mean of delta_b / R_c over its coalescing runs only
    (a coalescence-off run in the whole level is left out), at level 2's channel coefficient; the layer writes it.
    'zones_line' is the same with popbal.plume_law = 'line_force' in every level and in the layer, its level 2 scored
    on the mean diameter and axis velocity alone (the filling floors' count and flux left out). 'zones_drain' is
    'zones_line' with the roof's thickness from the drainage law: the layer and every level carry the form and the
    measured k in place of a thickness, and the roof's kernel is measured at each whole run's own law thickness
    (popbal's, recomputed here). The measured-zone steps and the fits are stubbed (tested above); this is the order
    and the choice of runs."""
    import tomllib
    from pathlib import Path

    import analysis.calibration.hierarchy as h
    from analysis.calibration.fit import LevelFit
    from analysis.calibration.layer import write_layer
    from analysis.calibration.registry import Registry
    from popbal.model import channel_closure
    from settler.cases import NO_CALIBRATION, load_case
    from tests.test_floor_layer import REMADE as reference
    from tests.test_floor_layer import _stored_layer

    for run, source, thickness in (("a", "demo_cell_25", 4e-3), ("b", "demo_feed_half_fine", 3e-3),
                                   ("off", "demo_no_coalescence_fine", 1e-3), ("kernel", "demo_cell_25", 1e-3)):
        _stored_layer(tmp_path / run, thickness, reference / source / "case.toml")
        (tmp_path / run / "timeseries.csv").write_text("time\n0\n")
    registry = Registry(holdouts=(), why={}, families={}, path=tmp_path / "holdouts.toml",
                        levels={"collision": ("kernel",), "transport": ("off",), "whole": ("a", "b", "off")})
    fixed_at, columns_at = {}, {}

    def fit_level(level, targets, case_files, parameters, start, fixed, **kw):
        fixed_at[level] = dict(fixed)
        columns_at[level] = kw["columns"]
        names = list(parameters)
        return LevelFit(level=level, runs=list(case_files), parameters=names, estimates={n: 0.5 for n in names},
                        standard_errors={n: 0.05 for n in names}, correlation=np.eye(len(names)), discrepancy=0.0,
                        chi2=1.0, residual_count=10, evaluations=3, status="converged", errors={},
                        gate={"passed": True, "reasons": []})

    monkeypatch.setattr(h, "cell_efficiency", lambda folder: {"efficiency": 0.8, "standard_error": 0.06, "merges": 9,
                                                              "quadrature_error": 0.0, "expected_collisions": 11.0,
                                                              "form": "cell"})
    monkeypatch.setattr(h, "seed_scatter", lambda reference_dir: {})
    monkeypatch.setattr(h, "dilution_from_zones", lambda runs, d: {"value": 4.94, "core_fraction": 0.041,
                                                                   "reynolds": 2.46, "runs": list(runs),
                                                                   "standard_errors": {"plume_dilution_reynolds": 0.5,
                                                                                       "channel_radius_factor": 0.2},
                                                                   "correlation": 0.5, "rms": 0.1,
                                                                   "per_run": {}, "excluded": {}})
    monkeypatch.setattr(h, "roof_from_zones", lambda runs, d: {"coefficient": 0.05, "thickness": 0.006,
                                                               "per_run": {}, "runs": list(runs),
                                                               "drainage_ratio": 2.5,
                                                               "drainage_per_run": {r: 2.5 for r in runs}})
    kernel_thickness = {}

    def roof_kernel(runs, d, thickness):
        kernel_thickness["value"] = thickness
        return {"efficiency": 1.9, "shear_coefficient": 3.0, "per_run": {}, "runs": list(runs)}

    monkeypatch.setattr(h, "roof_kernel_from_collisions", roof_kernel)
    monkeypatch.setattr(h, "load_target", lambda run, d, seed: run)
    monkeypatch.setattr(h, "fit_level", fit_level)
    result = h.calibrate_set(registry, tmp_path, progress=False, band_samples=0, closures=closures)
    law = None if closures == "zones_floor" else "line_force"
    assert fixed_at["transport"].get("popbal.plume_law") == law and fixed_at["whole"].get("popbal.plume_law") == law
    assert columns_at["whole"] == tuple(h.TARGET_COLUMNS)
    assert columns_at["transport"] == (("mean_diameter", "channel_velocity") if law else tuple(h.TARGET_COLUMNS))
    assert [f.parameters for f in result.levels] == [["channel_coefficient"], ["shear_coefficient"]]
    assert "popbal.bottom_layer_factor" not in fixed_at["transport"]
    assert result.floor["runs"] == ["a", "b"]
    radius = {r: channel_closure(load_case(tmp_path / r / "case.toml", {"case.calibration": NO_CALIBRATION,
                                                                        **fixed_at["transport"],
                                                                        "popbal.channel_coefficient": 0.5}))[0]
              for r in "ab"}
    expected = math.sqrt(4e-3 / radius["a"] * 3e-3 / radius["b"])
    assert fixed_at["whole"]["popbal.bottom_layer_factor"] == pytest.approx(expected, rel=1e-12)
    assert result.values["bottom_layer_factor"] == (result.floor["value"], result.floor["standard_error"])
    assert fixed_at["whole"]["popbal.channel_coefficient"] == 0.5
    layer = tomllib.loads(write_layer(result, tmp_path / "floor.toml", tmp_path / "holdouts.toml", "x").read_text())
    assert layer["popbal"]["bottom_layer_factor"] == pytest.approx(expected, rel=1e-12)
    assert "bottom layer from the floor layers: f_b" in result.summary()
    assert layer["popbal"].get("plume_law") == law and layer["popbal"]["confinement"] is True
    if closures != "zones_drain":
        assert kernel_thickness["value"] == 0.006 and fixed_at["whole"]["popbal.roof_thickness"] == 0.006
        assert "roof_thickness_form" not in layer["popbal"] and layer["popbal"]["roof_thickness"] == 0.006
        return
    for level in ("transport", "whole"):
        assert fixed_at[level]["popbal.roof_thickness_form"] == "drainage" and "popbal.roof_thickness" not in \
            fixed_at[level] and fixed_at[level]["popbal.roof_drainage_ratio"] == 2.5
    assert layer["popbal"]["roof_thickness_form"] == "drainage" and layer["popbal"]["roof_drainage_ratio"] == 2.5
    assert "roof_thickness" not in layer["popbal"]
    # the kernel at each whole run's own law thickness: delta = k U_s sqrt(mu / (c_L drho g j)) (no slag feed)
    g = 9.80665
    for run in ("a", "b"):
        case = load_case(tmp_path / run / "case.toml")
        drho, mu = case.matte.density - case.slag.density, case.slag_viscosity
        u_s = drho * g * case.feed.mean_diameter**2 / (18.0 * mu)
        j = case.feed.mass_rate / case.matte.density / (math.pi * (0.5 * case.geometry.inlet_diameter) ** 2)
        assert kernel_thickness["value"][run] == pytest.approx(2.5 * u_s * math.sqrt(mu / (0.05 * drho * g * j)),
                                                                rel=1e-9)
    assert kernel_thickness["value"]["b"] / kernel_thickness["value"]["a"] == pytest.approx(math.sqrt(2.0), rel=1e-9)


def _checkout_with_history():
    """This checkout's root, or a skip where git or its full history is not at hand (a shallow clone)."""
    import shutil
    import subprocess
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    shallow = subprocess.run(["git", "-C", str(root), "rev-parse", "--is-shallow-repository"], capture_output=True,
                             text=True) if shutil.which("git") else None
    if shallow is None or shallow.stdout.strip() != "false":
        pytest.skip("no full git history in this checkout")
    return root


def test_a_layer_names_the_reference_set_engine_it_was_fitted_to():
    """fitted_set_engine reads data/reference/engines.toml's [set] at a layer's code commit: the committed layer's
    set is a real engine (three 40-hex git trees) and a commit git does not know gives None, not an error (the
    calibration report then leaves its bands unchecked against today's runs)."""
    import re
    import tomllib

    from analysis.calibration.layer import fitted_set_engine

    root = _checkout_with_history()
    commit = tomllib.loads((root / "data" / "calibration" / "designed.toml").read_text())["provenance"]["code_commit"]
    engine = fitted_set_engine(commit, root)
    assert set(engine) == {"fulldem", "popbal", "settler"}
    assert all(re.fullmatch(r"[0-9a-f]{40}", tree) for tree in engine.values())
    assert fitted_set_engine("0" * 40, root) is None


def test_a_layer_says_whether_its_bands_were_drawn_over_the_parameters():
    """bands_draw_parameters: zones_core's layer (05f5cec) predates the fix of 757f27c, from which the hold-outs'
    bands run popbal at each draw, and is told apart from a commit after it (HEAD) and one git does not know (None);
    the fix commit's own parent predates it."""
    import tomllib

    from analysis.calibration.layer import BANDS_DRAW_FROM, bands_draw_parameters

    root = _checkout_with_history()
    commit = tomllib.loads((root / "data" / "calibration" / "zones_core.toml").read_text())["provenance"]["code_commit"]
    assert bands_draw_parameters(commit, root) is False
    assert bands_draw_parameters(BANDS_DRAW_FROM + "^", root) is False
    assert bands_draw_parameters(BANDS_DRAW_FROM, root) is True and bands_draw_parameters("HEAD", root) is True
    assert bands_draw_parameters("0" * 40, root) is None


@pytest.mark.parametrize("closures", ["zones_core", "zones_stir", "zones_scale"])
def test_zones_core_fits_the_slag_core_and_the_droplets_channel_at_the_whole_level_alone(closures, tmp_path,
                                                                                         monkeypatch):
    """'zones_core': no transport level (the plume laws as derived: channel_coefficient and return_flow_ratio 1,
    the shear coefficient as defined, 1); the whole level fits the compact slag core R_0 and the channel's radius
    factor, neither of which the fixed values may override; the floor's f_b is measured at the fit's start radii; the spread core's
    share is measured (stubbed here) with R_0 at its start; the layer is valid TOML that writes the 'inlet' form,
    the fitted radius factor and the measured share once each. 'zones_stir' fits the uniform turn's share with them
    and holds the channel's collision radii and the outer stirring measured (stubbed) at the start radii, with the
    spread share in place; the layer writes each once, with its unit, and they enter the bands' values, also as a
    band drawn from the written layer reads them (covariance_from_layer: each with its own variance)."""
    import tomllib

    import analysis.calibration.hierarchy as h
    from analysis.calibration.fit import LevelFit
    from analysis.calibration.layer import write_layer
    from analysis.calibration.registry import Registry
    from tests.test_floor_layer import REMADE as reference
    from tests.test_floor_layer import _stored_layer

    for run, source, thickness in (("a", "demo_cell_25", 4e-3), ("b", "demo_feed_half_fine", 3e-3),
                                   ("off", "demo_no_coalescence_fine", 1e-3), ("kernel", "demo_cell_25", 1e-3)):
        _stored_layer(tmp_path / run, thickness, reference / source / "case.toml")
        (tmp_path / run / "timeseries.csv").write_text("time\n0\n")
    registry = Registry(holdouts=(), why={}, families={}, path=tmp_path / "holdouts.toml",
                        levels={"collision": ("kernel",), "transport": ("off",), "whole": ("a", "b")})
    fixed_at, spread_at = {}, {}

    def fit_level(level, targets, case_files, parameters, start, fixed, **kw):
        fixed_at[level] = dict(fixed)
        names = list(parameters)
        assert start == {n: h.start_values(closures)[n] for n in names}
        return LevelFit(level=level, runs=list(case_files), parameters=names,
                        estimates={"plume_core_radius": 0.01, "channel_radius_factor": 0.45,
                                   "bottom_turning_share": 0.2, "plume_core_exponent": 0.25},
                        standard_errors={n: 0.001 for n in names}, correlation=np.eye(len(names)), discrepancy=0.0,
                        chi2=1.0, residual_count=8, evaluations=3, status="converged", errors={},
                        gate={"passed": True, "reasons": []})

    def spread(runs, d, fixed):
        spread_at.update(fixed)
        return {"value": 0.42, "standard_error": 0.01, "per_run": {"b": 0.42}, "runs": ["b"]}

    monkeypatch.setattr(h, "cell_efficiency", lambda folder: {"efficiency": 0.8, "standard_error": 0.06, "merges": 9,
                                                              "quadrature_error": 0.0, "expected_collisions": 11.0,
                                                              "form": "cell"})
    monkeypatch.setattr(h, "seed_scatter", lambda reference_dir: {})
    monkeypatch.setattr(h, "radius_factor_from_zones", lambda runs, d: {"value": 4.9, "core_fraction": 0.04,
                                                                        "runs": list(runs)})
    monkeypatch.setattr(h, "roof_from_zones", lambda runs, d: {"coefficient": 0.05, "thickness": 0.006,
                                                               "per_run": {}, "runs": list(runs),
                                                               "drainage_ratio": 2.5,
                                                               "drainage_per_run": {r: 2.5 for r in runs}})
    monkeypatch.setattr(h, "roof_kernel_from_collisions", lambda runs, d, thickness: {
        "efficiency": 1.9, "shear_coefficient": 3.0, "per_run": {}, "runs": list(runs)})
    stir_at = {}

    def radii(runs, d, fixed):
        stir_at.update(fixed)
        return {"compact": {"value": 0.006, "standard_error": 0.0004, "runs": ["a"]},
                "spread": {"value": 0.014, "standard_error": 0.0001, "runs": ["b"]}, "excluded": [],
                "with_excluded": None,
                "no_snapshot": [], "per_run": {r: {"collision_radius": 0.006, "clustering": 2.5} for r in runs}}

    monkeypatch.setattr(h, "collision_radius_from_clustering", radii)
    monkeypatch.setattr(h, "dispersion_from_suspension", lambda runs, d: {
        "value": 4.8e-4, "standard_error": 2e-5, "runs": ["b"], "undetermined": ["a"], "no_snapshot": [],
        "per_run": {"a": (math.nan, math.nan), "b": (4.8e-4, 2e-5)}})
    monkeypatch.setattr(h, "spread_share_from_groups", spread)
    monkeypatch.setattr(h, "load_target", lambda run, d, seed: run)
    monkeypatch.setattr(h, "fit_level", fit_level)
    result = h.calibrate_set(registry, tmp_path, progress=False, band_samples=0, closures=closures)
    assert list(fixed_at) == ["whole"]
    fitted = {"zones_core": ["plume_core_radius", "channel_radius_factor"],
              "zones_stir": ["plume_core_radius", "channel_radius_factor", "bottom_turning_share"],
              "zones_scale": ["plume_core_radius", "plume_core_exponent", "channel_radius_factor",
                              "bottom_turning_share"]}[closures]
    assert [f.parameters for f in result.levels] == [fitted]
    whole = fixed_at["whole"]
    assert not {"popbal.channel_radius_factor", "popbal.plume_core_radius"} & set(whole)
    assert whole["popbal.channel_radius_form"] == "inlet" and whole["popbal.channel_coefficient"] == 1.0
    assert whole["popbal.shear_coefficient"] == 1.0
    assert whole["popbal.spread_core_share"] == 0.42
    assert spread_at["popbal.plume_core_radius"] == h.start_values(closures)["plume_core_radius"]
    assert result.floor["runs"] == ["a", "b"]
    layer = tomllib.loads(write_layer(result, tmp_path / "core.toml", tmp_path / "holdouts.toml", "x").read_text())
    popbal = layer["popbal"]
    assert popbal["channel_radius_form"] == "inlet" and popbal["channel_radius_factor"] == 0.45
    assert popbal["plume_core_radius"] == 0.01 and popbal["spread_core_share"] == 0.42
    assert popbal["plume_core_column_share"] == 0.62 and popbal["spread_flux_reynolds"] == 0.66
    stirred = {"channel_collision_radius": 0.006, "spread_channel_collision_radius": 0.014, "outer_dispersion": 4.8e-4}
    if closures == "zones_core":
        assert not stir_at and result.stir is None and not set(stirred) & set(popbal)
        assert popbal["bottom_turning_share"] == 0.06 and "bottom_turning_form" not in popbal
        return
    core_start = 0.0095 if closures != "zones_scale" else 0.004464  # 9.5 mm at Re_Q 0.31 carried to 0.025, n 0.3
    assert stir_at["popbal.plume_core_radius"] == core_start and stir_at["popbal.channel_radius_factor"] == 0.5
    if closures == "zones_scale":  # the core's law at its start where the radii are measured, fitted in the layer
        assert stir_at["popbal.plume_core_exponent"] == 0.3 and stir_at["popbal.plume_core_reynolds"] == 0.025
        assert h.start_values("zones_scale")["plume_core_radius"] == stir_at["popbal.plume_core_radius"]
        assert whole["popbal.plume_fill_inlet_share"] == 0.78 and "popbal.plume_core_exponent" not in whole
        assert popbal["plume_core_exponent"] == 0.25 and popbal["plume_fill_inlet_share"] == 0.78
        assert popbal["plume_core_reynolds"] == 0.025
    assert stir_at["popbal.spread_core_share"] == 0.42
    assert {k: whole[f"popbal.{k}"] for k in stirred} == stirred == {k: popbal[k] for k in stirred}
    assert {k: result.values[k][0] for k in stirred} == stirred  # measured: into the bands
    assert popbal["bottom_turning_share"] == 0.2 and popbal["bottom_turning_form"] == "uniform"
    text = (tmp_path / "core.toml").read_text()
    assert all(text.split("[provenance]")[0].count(f"\n{k} = ") == 1 for k in stirred)
    assert "channel_collision_radius = 0.006  # m [derived]" in text and "outer_dispersion = 0.00048  # m^2/s" in text
    assert "outer stirring from the suspensions: D = 0.00048 +- 2e-05 m^2/s" in result.summary()
    from analysis.calibration.bands import covariance_from_layer

    estimates, covariance, keys, _ = covariance_from_layer(tmp_path / "core.toml")
    for key, se in (("channel_collision_radius", 0.0004), ("spread_channel_collision_radius", 0.0001),
                    ("outer_dispersion", 2e-5), ("bottom_layer_factor", result.floor["standard_error"])):
        i = keys.index(key)  # measured before the fit: drawn in the bands with its own variance
        assert estimates[key] == result.values[key][0] and covariance[i, i] == pytest.approx(se**2, rel=1e-12)
        assert not np.any(np.delete(covariance[i], i))
    for bad in ("plume_core_radius = [0.01, 0.001]", "outer_dispersion = 4.8e-4"):  # fitted too; not [value, se]
        key = bad.split(" = ")[0]
        (tmp_path / "bad.toml").write_text(text.replace("[provenance.measured]", f"[provenance.measured]\n{bad}", 1)
                                           if key == "plume_core_radius" else
                                           text.replace("\nouter_dispersion = [", f"\n{bad}\nx = [", 1))
        with pytest.raises(ValueError, match=f"bad.toml: \\[provenance.measured\\] {key} = .*allowed \\[value"):
            covariance_from_layer(tmp_path / "bad.toml")


def test_the_spread_core_share_is_measured_in_the_runs_the_regime_rule_spreads():
    """spread_share_from_groups on stored runs: at R_0 = 9.5 mm and Re_Q,c = 0.66, simple (rho_s Q / (mu R_0) =
    1.24) is spread and demo_cell_25 (0.31) is not; simple's share is its R* over its column radius, 47.4 mm / 112.8
    mm = 0.420 in data/reference/README.md's measured table; with no spread run it refuses."""
    from analysis.calibration.zones import spread_share_from_groups

    fixed = {"popbal.plume_core_radius": 0.0095, "popbal.spread_flux_reynolds": 0.66}
    got = spread_share_from_groups(["demo_cell_25", "simple"], "data/reference", fixed)
    assert got["runs"] == ["simple"] and got["value"] == pytest.approx(47.4 / 112.8, rel=5e-3)
    with pytest.raises(ValueError, match="no run of demo_cell_25 is spread"):
        spread_share_from_groups(["demo_cell_25"], "data/reference", fixed)


def test_a_holdouts_band_runs_popbal_at_each_parameter_draw_not_at_the_estimates(tmp_path, monkeypatch):
    """_score_holdouts: every fitted and measured value is in ``fixed``, which popbal's runs apply after the drawn
    values (fit.reduced_series); the draws must still reach popbal. With E = 1.0 +- 0.2 and no discrepancy, a model
    whose window means are E itself gives a 90 % band 2 x 1.645 x 0.2 = 0.658 wide (200 draws: within 20 %), where
    the estimates alone give a band of width 0; the point errors stay those at the estimates."""
    import types

    import analysis.calibration.fit as fit_module
    import analysis.calibration.hierarchy as h
    from analysis.calibration.fit import LevelFit
    from analysis.calibration.registry import Registry

    (tmp_path / "held").mkdir()
    (tmp_path / "held" / "timeseries.csv").write_text("time\n0\n")
    registry = Registry(holdouts=("held",), why={}, families={}, path=tmp_path / "holdouts.toml", levels={})
    target = types.SimpleNamespace(name="held", means=dict.fromkeys(h.TARGET_COLUMNS, 1.0), window=(0.0, 1.0))
    monkeypatch.setattr(h, "load_target", lambda run, d, seed: target)

    def fake_means(target, case_file, values, fixed):  # applied as fit.reduced_series applies them
        effective = {**{f"popbal.{k}": float(v) for k, v in values.items()}, **(fixed or {})}
        return dict.fromkeys(h.TARGET_COLUMNS, effective["popbal.collision_efficiency"])

    monkeypatch.setattr(fit_module, "reduced_means", fake_means)
    level = LevelFit(level="whole", runs=["a"], parameters=["plume_core_radius"], estimates={"plume_core_radius": 0.01},
                     standard_errors={"plume_core_radius": 0.001}, correlation=np.eye(1), discrepancy=0.0, chi2=1.0,
                     residual_count=4, evaluations=1, status="", errors={})
    values = {"collision_efficiency": (1.0, 0.2), "plume_core_radius": (0.01, 0.001), "outer_dispersion": (5e-4, 1e-4)}
    fixed = {"popbal.collision_efficiency": 1.0, "popbal.plume_core_radius": 0.01, "popbal.outer_dispersion": 5e-4,
             "popbal.confinement": True}
    errors, result = h._score_holdouts(registry, tmp_path, {}, fixed, values, [level], 200)
    assert errors["held"] == dict.fromkeys(h.TARGET_COLUMNS, 0.0)
    low, _, high = result["bands"]["held"]["droplet_count"]
    assert high - low == pytest.approx(2.0 * 1.645 * 0.2, rel=0.2) and low < 1.0 < high
