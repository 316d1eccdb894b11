"""The closure set 'zones_stir''s measured values (analysis.calibration.zones): the channel's collision radius per
regime pooled from the clustering measure, runs whose droplets collide no more often than mixed left out, and the
outer zone's stirring D pooled from the suspensions by the inverse-variance mean of the fitted 1 / D_e."""

import math

import numpy as np
import pandas as pd
import pytest

import analysis.channel_clustering as clustering
import analysis.suspension as suspension
from analysis.calibration.hierarchy import CORE, measured_closures
from analysis.calibration.registry import load_registry
from analysis.calibration.zones import collision_radius_from_clustering, dispersion_from_suspension

#: zones_core's closures at the fit's start radii, the regime rule on (simple and cubic spread, the demo does not).
START = {**CORE, "popbal.channel_radius_form": "inlet", "popbal.plume_core_radius": 0.0095,
         "popbal.channel_radius_factor": 0.5, "popbal.spread_core_share": 0.42}


def test_collision_radii_pool_by_regime_and_leave_out_runs_whose_droplets_fill_the_disk(monkeypatch):
    """b = R_eq / sqrt(S) per run (stubbed measures on the stored runs' cases); a regime's b the geometric mean, its
    standard error b x se(mean log b); S <= 1 excluded (popbal's law floors E_ch at E), the compact pool with it
    given beside; a run without a droplet snapshot (deep_w005_fine stores none) left out by name; with the spread
    run excluded too, the compact b would stand for simple's plume, and that is refused."""
    measured = {"demo_feed_half_fine": (4.0, 0.010), "demo_visc_half_fine": (2.25, 0.009),
                "demo_cell_25": (0.5, 0.008), "simple": (9.0, 0.036)}  # (S, R_eq [m])

    def fake_measure(folder, radius):
        s, r_eq = measured[folder.name]
        table = pd.DataFrame({"z": [0.0]})
        table.attrs.update(radius=r_eq, clustering=s)
        return table, {}

    monkeypatch.setattr(clustering, "measure_clustering", fake_measure)
    monkeypatch.setattr(clustering, "interior", lambda t: {"clustering": t.attrs["clustering"],
                                                           "collision_radius": t.attrs["radius"]
                                                           / math.sqrt(t.attrs["clustering"])})
    got = collision_radius_from_clustering(list(measured) + ["deep_w005_fine"], "data/reference", START)
    assert got["no_snapshot"] == ["deep_w005_fine"] and got["excluded"] == ["demo_cell_25"]
    assert got["with_excluded"]["value"] == pytest.approx((0.005 * 0.006 * 0.008 / math.sqrt(0.5)) ** (1 / 3),
                                                          rel=1e-12)
    assert got["compact"]["runs"] == ["demo_feed_half_fine", "demo_visc_half_fine"]
    assert got["compact"]["value"] == pytest.approx(math.sqrt(0.005 * 0.006), rel=1e-12)
    spread = np.std(np.log([0.005, 0.006]), ddof=1) / math.sqrt(2.0)
    assert got["compact"]["standard_error"] == pytest.approx(math.sqrt(0.005 * 0.006) * spread, rel=1e-12)
    assert got["spread"]["runs"] == ["simple"] and got["spread"]["value"] == pytest.approx(0.012, rel=1e-12)
    assert math.isnan(got["spread"]["standard_error"])
    measured["simple"] = (0.9, 0.036)
    with pytest.raises(ValueError, match="simple spread by the regime rule, and none gives the spread plume's"):
        collision_radius_from_clustering(list(measured), "data/reference", START)


def test_the_stirring_pools_the_determined_runs_by_the_inverse_variance_of_one_over_d(monkeypatch):
    """1 / D_e is the fitted coefficient (k = k0 + U / D_e), so the runs pool as its inverse-variance mean:
    D_e = 4e-4 +- 0.4e-4 and 6e-4 +- 1.2e-4 give 1 / D = (2500 / 250^2 + 1666.7 / 333.3^2) / (1 / 250^2 + 1 / 333.3^2);
    a run whose D_e is undetermined (NaN) or known to no better than half of itself is left out by name. The two
    pooled runs differ by 833 / sqrt(250^2 + 333^2) = 2.0 sigma: chi^2 = 4.0 for one degree of freedom, and the
    pooled standard error is widened by its square root."""
    fits = {"simple": (4e-4, 0.4e-4), "cubic": (6e-4, 1.2e-4), "demo_feed_half_fine": (math.nan, math.nan),
            "demo_visc_half_fine": (5e-4, 3e-4)}
    monkeypatch.setattr(suspension, "measure_suspension", lambda folder: (folder.name, {}))
    monkeypatch.setattr(suspension, "settling_fit", lambda name: {"diffusivity": fits[name][0],
                                                                  "diffusivity_error": fits[name][1]})
    got = dispersion_from_suspension(list(fits), "data/reference")
    w1, w2 = 1.0 / 250.0**2, 1.0 / (1.2e-4 / 6e-4**2) ** 2
    inverse = (2500.0 * w1 + (1.0 / 6e-4) * w2) / (w1 + w2)
    assert got["value"] == pytest.approx(1.0 / inverse, rel=1e-12)
    chi2 = w1 * (2500.0 - inverse) ** 2 + w2 * (1.0 / 6e-4 - inverse) ** 2
    assert chi2 == pytest.approx(4.0, rel=1e-9)
    assert got["standard_error"] == pytest.approx(math.sqrt(chi2) / math.sqrt(w1 + w2) / inverse**2, rel=1e-12)
    assert got["runs"] == ["simple", "cubic"]
    assert got["undetermined"] == ["demo_feed_half_fine", "demo_visc_half_fine"]
    monkeypatch.setattr(suspension, "settling_fit", lambda name: {"diffusivity": math.nan, "diffusivity_error": 1.0})
    with pytest.raises(ValueError, match="no run of simple determines the stirring diffusivity"):
        dispersion_from_suspension(["simple"], "data/reference")


def test_zones_stir_measures_its_closures_on_the_training_runs_alone():
    """On the stored set under the second registration: b from the compact demo runs (5.3-7.0 mm each at R_c 9.5 mm,
    analysis.channel_clustering's docstring), the spread b from simple and cubic (14.4-14.6 mm at 37.9 mm there;
    at the start's 37.5 mm within 4 %), deep_w002 excluded (its 5 mm channel, about 12 grid columns, gives S < 1),
    D between simple's and cubic's own (4.8 and 5.0e-4 m^2/s, analysis.suspension), the only runs that determine
    it."""
    registry = load_registry("data/calibration/holdouts.toml")
    measured = measured_closures(registry, "data/reference", "zones_stir")
    fixed, stir = measured["fixed"], measured["stir"]
    assert 5.3e-3 <= fixed["popbal.channel_collision_radius"] <= 7.0e-3
    assert 13.9e-3 <= fixed["popbal.spread_channel_collision_radius"] <= 14.6e-3
    assert stir["radius"]["spread"]["runs"] == ["simple", "cubic"]
    assert stir["radius"]["excluded"] == ["deep_w002"] and stir["radius"]["no_snapshot"] == ["deep_w005_fine"]
    assert stir["dispersion"]["runs"] == ["simple", "cubic"]
    d = {run: stir["dispersion"]["per_run"][run][0] for run in ("simple", "cubic")}
    assert min(d.values()) < fixed["popbal.outer_dispersion"] < max(d.values())
    assert fixed["popbal.bottom_turning_form"] == "uniform" and "popbal.bottom_turning_share" not in fixed
