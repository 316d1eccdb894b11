"""analysis.sweep.furnace_band: the copper conversion by hand, the trend ratio's cancellation of the common
discrepancy, and a furnace band whose draws all sit at one value collapsing onto the loss there."""

import math

import numpy as np
import pandas as pd
import pytest

from analysis.sweep import FURNACE_QUICK
from analysis.sweep import furnace_band as fb


def test_entrained_copper_by_hand():
    """0.41 kg/s of 60 % Cu matte into 20.4 kg/s of slag, 1 % of it lost: 0.0041 kg/s of matte, 0.00246 kg/s of Cu
    in 20.4041 kg/s of tapped slag and matte = 0.012056 wt %; all of it lost: 100 * 0.246 / 20.81."""
    assert fb.entrained_copper(0.01, 0.41, 20.4) == pytest.approx(100 * 0.0041 * 0.6 / 20.4041, rel=1e-12)
    assert fb.entrained_copper(1.0, 0.41, 20.4) == pytest.approx(100 * 0.41 * 0.6 / 20.81, rel=1e-12)
    assert fb.entrained_copper(0.0, 0.41, 20.4) == 0.0
    assert 0.55 <= fb.MATTE_GRADE <= 0.70 and fb.MATTE_GRADE_RANGE == (0.55, 0.70)


def test_trend_ratio_cancels_a_factor_common_to_both_ends():
    """Losses at the two ends of a key that differ by exactly 3x in every draw, each draw scaled by its own
    (discrepancy) factor common to both ends: the ratio is 3 in every quantile and the trend is resolved; a flat
    trend (ratio 1 within +-1 % scatter) is not."""
    factors = np.exp(0.8 * np.random.default_rng(1).normal(size=50))
    flat = 1.0 + 0.01 * np.random.default_rng(2).uniform(-1, 1, 50)
    table = pd.DataFrame([
        {"key": "a", "value": 1.0, "losses": 1e-3 * factors}, {"key": "a", "value": 2.0, "losses": 3e-3 * factors},
        {"key": "b", "value": 1.0, "losses": 1e-3 * factors}, {"key": "b", "value": 2.0, "losses": 1e-3 * factors * flat},
    ])
    ratios = fb.trend_ratios(table).set_index("key")
    for column in ("ratio_low", "ratio_median", "ratio_high"):
        assert ratios.loc["a", column] == pytest.approx(3.0, rel=1e-12)
    assert bool(ratios.loc["a", "resolved"]) and not bool(ratios.loc["b", "resolved"])


def test_band_without_uncertainty_is_the_loss_at_the_estimate(tmp_path, monkeypatch):
    """A layer with no spread and no discrepancy: every draw is the layer's collision efficiency, so the band's
    three quantiles equal the loss of the furnace at that efficiency (coarse resolution, 3 draws)."""
    import re

    from settler import cases
    from settler.cases import case_with_overrides

    text = cases.calibration_path("designed").read_text(encoding="utf-8")
    text = re.sub(r"^standard_error = [^ ]+", "standard_error = 0.0", text, flags=re.M)
    text = re.sub(r"^discrepancy = [^ ]+", "discrepancy = 0.0", text, flags=re.M)
    layer = tmp_path / "certain.toml"
    layer.write_text(text, encoding="utf-8")
    real = cases.calibration_path
    monkeypatch.setattr(cases, "calibration_path", lambda name: layer if name == "certain" else real(name))
    band = fb.loss_band(FURNACE_QUICK, "certain", samples=3)
    efficiency = float(re.search(r"^collision_efficiency = ([^ ]+)", text, flags=re.M).group(1))
    expected = fb._loss(case_with_overrides("furnace", {**FURNACE_QUICK, "popbal.collision_efficiency": efficiency}))
    np.testing.assert_allclose(band["quantiles"], expected, rtol=1e-9)
    assert band["at_estimates"] == pytest.approx(expected, rel=1e-9) and band["delta"] == 0.0
    assert math.isfinite(band["copper"][1]) and band["copper"][1] > 0.0
