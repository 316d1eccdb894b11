"""The controlling groups of analysis.groups against the closed forms they come from (shared/reference/
reduced-model.md section 2: the confined Stokes plume's c(R/a) table, the Richardson-Zaki flux peak), and the
reference set's design file: every run a valid case the full engine accepts."""

import math

import pytest

from analysis.groups import KYNCH_PEAK, confinement_factor, design_groups, measured_groups
from settler.cases import load_case


def test_confinement_factor_reproduces_the_confined_plume_table():
    # reduced-model.md: R/a 20, 10, 5, 3.3, 2 -> c 1.39, 1.05, 0.71, 0.51, 0.29 (two decimals)
    for ratio, c in ((20, 1.39), (10, 1.05), (5, 0.71), (3.3, 0.51), (2, 0.29)):
        assert confinement_factor(ratio) == pytest.approx(c, abs=0.005)
    assert math.isnan(confinement_factor(1.0))


def test_kynch_peak_is_the_richardson_zaki_maximum():
    # phi (1 - phi)^4.65 peaks at phi = 1/5.65 = 0.177 with 0.0715 (reduced-model.md, feed layer)
    best = max(p / 10000 * (1 - p / 10000) ** 4.65 for p in range(1, 10000))
    assert KYNCH_PEAK == pytest.approx(best, rel=1e-6) and KYNCH_PEAK == pytest.approx(0.0715, abs=5e-5)


def test_design_groups_of_the_demo():
    case = load_case("demo")
    g = design_groups(case)
    d, mu = case.feed.mean_diameter, case.slag_viscosity
    u_s = (case.matte.density - case.slag.density) * 9.80665 * d * d / (18 * mu)
    assert g["stokes_velocity"] == pytest.approx(u_s, rel=1e-12)
    a = case.geometry.inlet_diameter / 2
    flux = case.feed.mass_rate / case.matte.density / (math.pi * a * a)
    assert g["kynch_ratio"] == pytest.approx(flux / (0.0715455 * u_s), rel=1e-5)
    assert g["column_to_inlet"] == pytest.approx(0.1 / math.sqrt(math.pi) / a, rel=1e-12)
    # twice the feed: the plume velocity grows as its square root
    double = design_groups(load_case("demo", [f"feed.mass_rate={2 * case.feed.mass_rate!r}"]))
    assert double["plume_velocity"] == pytest.approx(math.sqrt(2) * g["plume_velocity"], rel=1e-12)


def test_measured_groups_take_the_last_third_of_the_run():
    import pandas as pd

    case = load_case("demo")
    frame = pd.DataFrame({"time": [0.0, 1.0, 2.0, 3.0], "channel_radius": [1.0, 1.0, 0.01, 0.02],
                          "channel_velocity": [9.0, 9.0, 0.03, 0.05]})
    g = measured_groups(frame, case)
    assert g["channel_radius"] == pytest.approx(0.015) and g["channel_velocity"] == pytest.approx(0.04)
    assert g["channel_reynolds"] == pytest.approx(case.slag.density * 0.04 * 0.015 / case.slag_viscosity)


def test_the_reference_design_is_a_set_of_valid_full_runs():
    from pathlib import Path

    from analysis.sweep import load_run_set
    from fulldem.driver import check_case

    path = Path(__file__).resolve().parents[1] / "data" / "reference" / "design.toml"
    runs = load_run_set(path).runs
    assert {"simple", "cubic", "deep", "kernel"} <= {r.name for r in runs}
    for run in runs:
        check_case(run.case)  # raises CaseError on a case the engine refuses
    kernel = next(r for r in runs if r.name == "kernel")
    assert kernel.droplets is not None and Path(kernel.droplets).is_file()


def test_the_readme_group_table_is_the_design_files():
    """data/reference/README.md's a priori table is what `python -m analysis.groups data/reference/design.toml`
    prints, row for row: a run added to or changed in the design file shows up in the README (it had kept simple
    at 45 s and cubic at 75 s after the design file moved them to 60 and 160 s, and lacked deep_w015)."""
    from pathlib import Path

    from analysis.groups import design_table

    readme = Path("data/reference/README.md").read_text(encoding="utf-8").splitlines()
    start = next(k for k, line in enumerate(readme) if line.startswith("| run | family | case and overrides"))
    stop = next((k for k in range(start, len(readme)) if not readme[k].startswith("|")), len(readme))
    assert readme[start:stop] == design_table("data/reference/design.toml").splitlines()


def test_measured_groups_over_a_given_window():
    import pandas as pd

    case = load_case("demo")
    frame = pd.DataFrame({"time": [0.0, 1.0, 2.0, 3.0], "channel_radius": [1.0, 0.01, 0.03, 9.0],
                          "channel_velocity": [9.0, 0.02, 0.04, 9.0]})
    g = measured_groups(frame, case, (1.0, 2.0))
    assert g["channel_radius"] == pytest.approx(0.02) and g["channel_velocity"] == pytest.approx(0.03)


def test_the_measured_table_reads_each_stored_run_over_its_steady_window_and_hides_the_holdouts(tmp_path, capsys):
    """`python -m analysis.groups data/reference --measured`: a stored run's row is its steady window's means (the
    axis velocity the time series' own mean there), its floor layer's thickness as stored; a registered hold-out is
    named without a value; a file where a folder is wanted is refused in one line."""
    import shutil

    from analysis import load_run
    from analysis.floor_layer import read_floor_layer
    from analysis.groups import main, stored_measured_groups
    from analysis.steady import window_of

    for name in ("demo_cell_25", "demo_feed_half_fine"):
        shutil.copytree(f"data/reference/{name}", tmp_path / name)
    groups = stored_measured_groups(tmp_path / "demo_cell_25")
    series = load_run(tmp_path / "demo_cell_25").timeseries
    (start, end), steady = window_of(series)
    inside = series[(series["time"] >= start) & (series["time"] <= end)]
    assert steady and groups["window"] == (start, end)
    assert groups["channel_velocity"] == pytest.approx(inside["channel_velocity"].mean(), rel=1e-12)
    thickness = read_floor_layer(tmp_path / "demo_cell_25" / "floor_layer.csv")[1]["thickness"]
    assert groups["floor_to_channel"] == pytest.approx(thickness / groups["channel_radius"], rel=1e-12)
    assert 0.5 < groups["stokes_ratio"] < 1.5  # the axis follows the Stokes flow its droplets drive (plume_force)
    registry = tmp_path / "holdouts.toml"
    registry.write_text('[holdouts]\nruns = ["demo_feed_half_fine"]\n[holdouts.why]\ndemo_feed_half_fine = "test"\n'
                        '[families]\n[levels]\ncollision = []\ntransport = []\nwhole = ["demo_cell_25"]\n')
    assert main([str(tmp_path), "--measured", "--registry", str(registry)]) == 0
    rows = {line.split("|")[1].strip(): line for line in capsys.readouterr().out.splitlines()[2:]}
    assert set(rows) == {"demo_cell_25", "demo_feed_half_fine"}
    assert "not shown" in rows["demo_feed_half_fine"] and not any(c.isdigit() for c in
                                                                  rows["demo_feed_half_fine"].split("not shown")[1])
    assert f"{1e3 * groups['channel_velocity']:.3g}" in rows["demo_cell_25"]
    assert main([str(registry), "--measured"]) == 2 and "allowed: a folder" in capsys.readouterr().err


def test_the_readme_measured_table_is_the_stored_runs():
    """data/reference/README.md's measured table is what `python -m analysis.groups data/reference --measured`
    prints from the stored runs, row for row (a run restored or re-measured shows up in the README)."""
    from pathlib import Path

    from analysis.calibration.registry import load_registry
    from analysis.groups import measured_table

    readme = Path("data/reference/README.md").read_text(encoding="utf-8").splitlines()
    start = next(k for k, line in enumerate(readme) if line.startswith("| run | window [s] |"))
    stop = next((k for k in range(start, len(readme)) if not readme[k].startswith("|")), len(readme))
    table = measured_table("data/reference", load_registry("data/calibration/holdouts.toml").holdouts)
    assert readme[start:stop] == table.splitlines()
