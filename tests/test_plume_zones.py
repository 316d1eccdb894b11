"""analysis.plume_zones: a band's droplets split into the plume's core (within the half-volume radius), its skirt (out
to the return radius) and the return flow, with their loads and volume-weighted velocities, on a constructed run."""

import math

import numpy as np
import pytest

from analysis.plume_zones import (measure_plume_zones, read_plume_zones, shares, split_band, write_plume_zones)
from settler.output import CHANNEL_PROFILE, ZONE_PROFILE, band_edges, write_table
from tests.test_floor_lift import _run_folder

D = 5e-4  # every droplet's diameter [m]
VOLUME = math.pi / 6.0 * D**3


def test_split_band_puts_droplets_inside_out_and_keeps_the_core_without_a_return_radius():
    """Droplets at 2, 10 and 30 mm split at a = 5 mm and r_0 = 20 mm one to a part; with r_0 inside the core the skirt
    is empty and the return flow starts at a; without r_0 everything beyond a is skirt. Volumes and fluxes add up."""
    r, volume, down = np.array([2e-3, 10e-3, 30e-3]), np.array([1.0, 2.0, 3.0]), np.array([0.04, 0.02, -0.001])
    got = split_band(r, volume, down, 5e-3, 20e-3)
    assert got == {"core": (1.0, 0.04), "skirt": (2.0, 0.04), "return": (3.0, pytest.approx(-0.003))}
    inside = split_band(r, volume, down, 5e-3, 3e-3)
    assert inside["skirt"] == (0.0, 0.0) and inside["return"][0] == 5.0
    none = split_band(r, volume, down, 5e-3, math.nan)
    assert none["skirt"][0] == 5.0 and none["return"] == (0.0, 0.0)


def test_a_constructed_plume_is_measured_stored_and_read_back(tmp_path):
    """One snapshot of the demo (100 mm high, axis at the middle): in the band 40-50 mm, 200 droplets at 1-5 mm from
    the axis falling at 40 mm/s, 100 at 12-20 mm at 20 mm/s and 100 at 30-45 mm rising at 1 mm/s; the return radius 25
    mm. The half-volume radius falls between 5 and 12 mm, so the core holds the 200 (share 0.5, 40 / 45 of the axis
    velocity), the skirt and the return flow a quarter each; the loads are the counts' volume over the band's 10 mm;
    the other bands are empty (NaN velocities); the file round-trips; a profile without a band's row is refused by
    name, not read as a band without return flow."""
    rng = np.random.default_rng(5)
    radius = np.concatenate([np.linspace(1e-3, 5e-3, 200), np.linspace(12e-3, 20e-3, 100),
                             np.linspace(30e-3, 45e-3, 100)])
    angle = rng.uniform(0.0, 2.0 * math.pi, radius.size)
    down = np.concatenate([np.full(200, 0.04), np.full(100, 0.02), np.full(100, -0.001)])
    n = radius.size
    points = np.column_stack([0.05 + radius * np.cos(angle), 0.05 + radius * np.sin(angle),
                              rng.uniform(0.041, 0.049, n)])
    data = {"diameter": np.full(n, D), "velocity": np.column_stack([np.zeros((n, 2)), -down]),
            "density": np.full(n, 5100.0), "age": np.zeros(n), "ident": np.arange(n, dtype=float),
            "merged": np.zeros(n)}
    folder = tmp_path / "run"
    _run_folder(folder, [(20.0, points, data)])
    centres = 0.5 * (band_edges(0.1)[:-1] + band_edges(0.1)[1:])
    write_table([{"time": 20.0, "z": z, "channel_radius": math.nan, "channel_velocity": 0.045 if abs(z - 0.045) < 1e-9
                  else 0.0, "droplet_volume": 0.0} for z in centres], CHANNEL_PROFILE, folder / "channel_profile.csv")
    write_table([{"time": 20.0, "z": z, "volume_fraction": 0.0, "core_volume_fraction": math.nan,
                  "upward_slag_flux": 0.0, "downward_slag_flux": 0.0, "return_radius": 0.025, "rising_volume": 0.0}
                 for z in centres], ZONE_PROFILE, folder / "zone_profile.csv")
    table, meta = measure_plume_zones(folder, (15.0, 20.0))
    assert meta["snapshots"] == [20.0]
    band = table.iloc[4]
    assert band["z"] == pytest.approx(0.045)
    for part, count, velocity in (("core", 200, 0.04), ("skirt", 100, 0.02), ("return", 100, -0.001)):
        assert band[f"{part}_load"] == pytest.approx(count * VOLUME / 0.01, rel=1e-12)
        assert band[f"{part}_velocity"] == pytest.approx(velocity, rel=1e-9)
    share = shares(table).iloc[4]
    assert [share["core_share"], share["skirt_share"], share["return_share"]] == pytest.approx([0.5, 0.25, 0.25])
    assert share["core_speed"] == pytest.approx(0.04 / 0.045)
    assert table.drop(index=4)[["core_load", "skirt_load", "return_load"]].to_numpy().sum() == 0.0
    assert table.drop(index=4)["core_velocity"].isna().all()
    path = write_plume_zones(folder, tmp_path, (15.0, 20.0))
    back, back_meta = read_plume_zones(path)
    assert back_meta["window"] == (15.0, 20.0) and back_meta["snapshots"] == [20.0]
    assert np.allclose(back["core_load"], table["core_load"], rtol=1e-6, equal_nan=True)
    with pytest.raises(ValueError, match="no droplet snapshot within 0-10 s"):
        measure_plume_zones(folder, (0.0, 10.0))
    write_table([{"time": 20.0, "z": z, "volume_fraction": 0.0, "core_volume_fraction": math.nan,
                  "upward_slag_flux": 0.0, "downward_slag_flux": 0.0, "return_radius": 0.025, "rising_volume": 0.0}
                 for z in centres[:-1]], ZONE_PROFILE, folder / "zone_profile.csv")  # a band's row missing
    with pytest.raises(ValueError, match=r"zone_profile.csv: no row at 20 s for the band centred at z = 0.095 m"):
        measure_plume_zones(folder, (15.0, 20.0))


def test_the_window_measure_command_line_reports_each_run_and_refuses_bad_input_in_one_line(capsys):
    """analysis.steady.window_measure_main (the command line of floor_layer, floor_lift and plume_zones): each run's
    measure over the --window given is reported in order; a bad window and a failing run exit 2 with one line naming
    the value or the run, and no run after a failing one is measured."""
    from analysis.steady import window_measure_main

    seen = []

    def measure(folder, window):
        if folder == "bad":
            raise ValueError("no droplet snapshot")
        seen.append((folder, window))
        return "table", {"window": window}

    def report(folder, table, meta):
        print(f"{folder} {table} {meta['window']}")

    args = ("prog", "what", "runs", measure, report)
    assert window_measure_main(["a", "b", "--window", "10:20"], *args) == 0
    assert seen == [("a", (10.0, 20.0)), ("b", (10.0, 20.0))]
    assert capsys.readouterr().out.splitlines() == ["a table (10.0, 20.0)", "b table (10.0, 20.0)"]
    assert window_measure_main(["a", "--window", "20:10"], *args) == 2
    assert "prog: --window '20:10': allowed START:END" in capsys.readouterr().err
    seen.clear()
    assert window_measure_main(["bad", "a"], *args) == 2
    assert capsys.readouterr().err.strip() == "prog: bad: no droplet snapshot" and seen == []


def test_the_plume_speed_ratio_is_the_moving_droplets_volume_weighted_speed_over_the_axis():
    """t over the middle bands: core and skirt weighted by their loads, the return flow left out; by hand."""
    import pandas as pd

    from analysis.plume_zones import plume_speed_ratio

    n = 10
    table = pd.DataFrame({"z": np.arange(n) * 0.01, "axis_velocity": np.full(n, 0.05),
                          "core_load": np.full(n, 3e-6), "skirt_load": np.full(n, 1e-6), "return_load": np.full(n, 9.0),
                          "core_velocity": np.full(n, 0.04), "skirt_velocity": np.full(n, 0.02),
                          "return_velocity": np.full(n, -5.0)})
    table.loc[0, "core_velocity"] = 99.0  # outside the middle bands: not counted
    assert plume_speed_ratio(table) == pytest.approx((3 * 0.04 + 1 * 0.02) / 4 / 0.05, rel=1e-12)
