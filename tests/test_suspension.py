"""analysis.suspension: each size class's vertical profile away from the plume, fitted as ln n = a - k z, against
profiles of known slope (the steady Mason-Weaver profile n ∝ exp(-U z / D) of a settling, eddy-diffused column)."""

import math

import numpy as np
import pytest

from analysis.suspension import EDGES, HEIGHT_BINS, fit_slope, main, size_profiles


def test_an_exact_exponential_gives_its_slope_and_too_few_droplets_give_none():
    z = np.linspace(0.01, 0.09, 8)
    assert fit_slope(z, 1000.0 * np.exp(-12.5 * z))[0] == pytest.approx(12.5, rel=1e-12)
    assert math.isnan(fit_slope(z, [4, 4, 4, 50, 4, 4, 40, 4])[0])  # two bins of at least 5 droplets


def _column(rng, count, diffusivity, velocity, height, centre, inner, outer):
    """``count`` droplets of settling velocity ``velocity`` [m/s] in the steady profile exp(-U z / D) over
    0-``height``, spread uniformly over the ring inner < r < outer about ``centre``."""
    k = velocity / diffusivity
    u = rng.random(count)
    z = -np.log(1.0 - u * (1.0 - math.exp(-k * height))) / k  # inverse of the truncated exponential's CDF
    r = np.sqrt(rng.uniform(inner**2, outer**2, count))
    phi = rng.uniform(0.0, 2.0 * math.pi, count)
    return np.column_stack([centre[0] + r * np.cos(phi), centre[1] + r * np.sin(phi), z])


def test_droplets_in_mason_weavers_profile_give_back_their_diffusivity_size_by_size():
    """Three classes (0.5, 0.9 and 1.5 mm, U = 0.6, 1.9 and 4.7 mm/s) each in exp(-U z / D) with D = 2e-4 m^2/s over
    0.2 m, 40 000 droplets a class beyond the 45 mm exclusion, and as many again inside it in a uniform column (the
    plume, to be left out): each fitted D within 3 standard errors of 2e-4 (about 1-3 %)."""
    rng = np.random.default_rng(7)
    centre, height, diffusivity = (0.1, 0.1), 0.2, 2e-4
    positions, diameters, velocities = [], [], []
    for d, u in ((0.5e-3, 0.6e-3), (0.9e-3, 1.9e-3), (1.5e-3, 4.7e-3)):
        positions += [_column(rng, 40000, diffusivity, u, height, centre, 0.046, 0.1),
                      np.column_stack([centre[0] + rng.uniform(-0.02, 0.02, 40000),
                                       centre[1] + rng.uniform(-0.02, 0.02, 40000),
                                       rng.uniform(0.0, height, 40000)])]
        diameters += [np.full(80000, d)]
        velocities += [np.full(80000, u)]
    table = size_profiles([(np.vstack(positions), np.concatenate(diameters), np.concatenate(velocities))],
                          centre, 0.045, height)
    assert len(table) == len(EDGES) - 1
    for d, u in ((0.5e-3, 0.6e-3), (0.9e-3, 1.9e-3), (1.5e-3, 4.7e-3)):
        row = table[(table["diameter_low"] <= d) & (d < table["diameter_high"])].iloc[0]
        assert row["settling_velocity"] == pytest.approx(u, rel=1e-12)
        k = u / diffusivity
        assert abs(row["slope"] - k) < 3.0 * row["slope_error"], (d, row["slope"], k, row["slope_error"])
        assert row["diffusivity"] == pytest.approx(u / row["slope"], rel=1e-12)
        share = (math.exp(-k * 0.1 * height) - math.exp(-k * 0.9 * height)) / (1.0 - math.exp(-k * height))
        assert row["droplets"] == pytest.approx(40000 * share, rel=0.05)  # the plume's droplets left out
    assert HEIGHT_BINS == 8


def test_bad_input_is_refused_in_one_line(capsys):
    assert main(["data/reference/simple", "--exclude", "-1"]) == 2
    assert "--exclude -1.0" in capsys.readouterr().err
    assert main(["data/reference/deep_fine"]) == 2  # a pre-registered hold-out
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is a pre-registered hold-out" in err[0]
    assert main(["data/reference/deep_w005_fine"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith("(it stores none)")


def test_classes_on_one_stirred_line_give_back_k0_and_the_diffusivity():
    """Slopes exactly k0 + U / D_e (k0 = 5 /m, D_e = 5e-4 m^2/s) at four velocities: the fit returns both to 1e-9 and
    a chi2 of zero; two classes are too few."""
    import pandas as pd

    from analysis.suspension import settling_fit

    u = np.array([0.6e-3, 1.1e-3, 1.9e-3, 4.7e-3])
    table = pd.DataFrame({"diameter_low": [0.4e-3, 0.6e-3, 0.8e-3, 1.3e-3], "diameter_high": [0.6e-3, 0.8e-3, 1e-3,
                                                                                              2e-3],
                          "settling_velocity": u, "slope": 5.0 + u / 5e-4, "slope_error": [0.1, 0.2, 0.2, 0.5]})
    fit = settling_fit(table)
    assert fit["k0"] == pytest.approx(5.0, rel=1e-9) and fit["diffusivity"] == pytest.approx(5e-4, rel=1e-9)
    assert fit["chi2_per_dof"] == pytest.approx(0.0, abs=1e-12) and len(fit["classes"]) == 4
    assert math.isnan(settling_fit(table.iloc[:2])["diffusivity"])
