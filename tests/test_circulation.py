"""analysis.circulation: the slag a full run's plume entrains and detrains by height (the downflux through each cell
layer, checked against a field built to carry a known rate) and the droplets counted by ident as they pass between
the roof, the floor and the rising and sinking slag (checked against passages placed by hand)."""

import json

import meshio
import numpy as np
import pytest

from analysis.circulation import PASSAGES, REGIONS, main, measure_circulation
from settler.cases import load_case
from settler.output import time_series_frame, write_time_series
from settler.vti import image_bytes

SHAPE = (10, 10, 10)  # slag cells over the demo's 0.1 m box
SPACING = 0.01  # [m]
SINKING = (slice(3, 7), slice(3, 7))  # the 16 middle columns sink, the 84 around them rise
DOWNFLUX = 1e-6 * np.arange(1, 11)  # the rate sinking through each cell layer, bottom to top [m^3/s]


def _slag():
    """(nx, ny, nz, 3) cell velocity carrying DOWNFLUX down the middle and the same rate up around it."""
    area = SPACING**2
    velocity = np.zeros((*SHAPE, 3))
    rising = np.ones(SHAPE[:2], dtype=bool)
    rising[SINKING] = False
    for k, q in enumerate(DOWNFLUX):
        velocity[..., k, 2] = np.where(rising, q / (84 * area), -q / (16 * area))
    return velocity


def _centre(i, j, k):
    return [(i + 0.5) * SPACING, (j + 0.5) * SPACING, (k + 0.5) * SPACING]


def _run_folder(folder, snapshots, idents=True):
    """A synthetic full-run folder of the demo case: ``snapshots`` [(time, {ident: (i, j, k) cell})]."""
    folder.mkdir()
    (folder / "case.toml").write_text(load_case("demo").to_toml())
    (folder / "metadata.json").write_text(json.dumps({"engine": "fulldem", "command": "settler full demo --out X"}))
    times = [t for t, _ in snapshots]
    rows = [{"time": t, "droplet_count": 100.0, "mass_fed": 1e-3 * t} for t in np.linspace(0.0, times[-1], 31)]
    write_time_series(time_series_frame(rows), folder / "timeseries.csv")
    entries = []
    for index, (time, where) in enumerate(snapshots):
        ident = np.array(sorted(where), dtype=float)
        points = np.array([_centre(*where[int(i)]) for i in ident])
        n = len(ident)
        data = {"diameter": np.full(n, 5e-4), "velocity": np.zeros((n, 3)), "density": np.full(n, 5100.0),
                "age": np.zeros(n), "merged": np.zeros(n)} | ({"ident": ident} if idents else {})
        mesh = meshio.Mesh(points, [("vertex", np.arange(n).reshape(-1, 1))], point_data=data)
        meshio.write(folder / f"droplets_{index:05d}.vtu", mesh, file_format="vtu", binary=True)
        (folder / f"fluid_{index:05d}.vti").write_bytes(image_bytes(SHAPE, (0.0, 0.0, 0.0), SPACING,
                                                                    {"velocity": _slag()}))
        entries += [f'    <DataSet timestep="{time:.9g}" part="0" file="droplets_{index:05d}.vtu"/>',
                    f'    <DataSet timestep="{time:.9g}" part="1" file="fluid_{index:05d}.vti"/>']
    (folder / "snapshots.pvd").write_text('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n'
                                          "  <Collection>\n" + "\n".join(entries) + "\n  </Collection>\n</VTKFile>\n")


def _snapshots():
    """At 10 s: 50 droplets rising at 35 mm, 30 sinking at 55 mm, 20 on the floor, 5 in the roof. By 11 s: 10 of
    the rising ones sink at 75 mm, 5 of the sinking ones rise at 15 mm and the other 25 are gone, 4 of the floor's
    rise at 25 mm. At 12 s nothing has moved."""
    first = {i: (0, 0, 3) for i in range(50)} | {i: (4, 4, 5) for i in range(100, 130)}
    first |= {i: (8, 0, 0) for i in range(200, 220)} | {i: (4, 5, 9) for i in range(300, 305)}
    second = {i: (5, 6, 7) for i in range(10)} | {i: (0, 0, 3) for i in range(10, 50)}
    second |= {i: (9, 9, 1) for i in range(100, 105)} | {i: (0, 9, 2) for i in range(200, 204)}
    second |= {i: (8, 0, 0) for i in range(204, 220)} | {i: (4, 5, 9) for i in range(300, 305)}
    return [(10.0, first), (11.0, second), (12.0, second)]


def test_the_downflux_profile_is_the_rate_the_field_carries(tmp_path):
    _run_folder(tmp_path / "run", _snapshots())
    result = measure_circulation(tmp_path / "run", (10.0, 12.0))
    profile = result["downflux"]
    assert profile.z.to_numpy() == pytest.approx(0.005 + 0.01 * np.arange(10))
    assert profile.downflux.to_numpy() == pytest.approx(DOWNFLUX, rel=1e-6)  # float32 in the file
    assert profile.sinking_share.to_numpy() == pytest.approx(np.full(10, 0.16))


@pytest.mark.parametrize("lag", [1, 2])
def test_droplet_passages_are_counted_per_second_at_the_heights_they_happen(tmp_path, lag):
    """The passages all happen between 10 and 11 s, so their rate per second over 10-12 s is the same at lag 1 and 2
    (a real passage, not flicker)."""
    _run_folder(tmp_path / "run", _snapshots())
    result = measure_circulation(tmp_path / "run", (10.0, 12.0), lag)
    flows = result["flows"].set_index(["source", "destination"]).rate
    span = 2.0
    assert flows["up", "down"] == pytest.approx(10 / span) and flows["down", "up"] == pytest.approx(5 / span)
    assert flows["down", "gone"] == pytest.approx(25 / span) and flows["floor", "up"] == pytest.approx(4 / span)
    # staying put: both pairs at lag 1 (40 + 49 rising, 5 + 5 in the roof), the one pair 10 -> 12 s at lag 2
    assert flows["up", "up"] == pytest.approx({1: 89, 2: 40}[lag] / span)
    assert flows["roof", "roof"] == pytest.approx({1: 10, 2: 5}[lag] / span)
    # every droplet of a pair's first snapshot goes somewhere: 105 at 10 s, 80 at 11 s
    assert flows.sum() == pytest.approx({1: 105 + 80, 2: 105}[lag] / span)
    occupancy = result["occupancy"]
    expected = {1: {"up": (50 + 49) / 2, "down": (30 + 10) / 2, "floor": (20 + 16) / 2, "roof": 5.0},
                2: {"up": 50.0, "down": 30.0, "floor": 20.0, "roof": 5.0}}[lag]
    assert occupancy == pytest.approx(expected)
    heights = result["heights"].set_index("z_low")
    # 35 -> 75 mm: mean 55 mm; 55 -> 15 mm: 35 mm; floor 5 -> 25 mm: 15 mm
    for passage, z_low, rate in (("up->down", 0.05, 10 / span), ("down->up", 0.03, 5 / span),
                                 ("floor->up", 0.01, 4 / span)):
        column = heights[passage]
        assert column[z_low] == pytest.approx(rate) and column.drop(z_low).sum() == 0.0
    assert set(REGIONS) == {"roof", "floor", "up", "down"} and len(PASSAGES) == 3


def test_refusals_name_what_is_missing(tmp_path, capsys):
    _run_folder(tmp_path / "run", _snapshots(), idents=False)
    assert main([str(tmp_path / "run"), "--window", "10:12"]) == 2
    assert "carries no idents" in capsys.readouterr().err
    _run_folder(tmp_path / "other", _snapshots())
    assert main([str(tmp_path / "other"), "--window", "10:12", "--lag", "3"]) == 2
    assert "needs at least lag + 1 = 4 snapshots" in capsys.readouterr().err
    assert main([str(tmp_path / "other"), "--window", "12:10"]) == 2
    assert "--window '12:10'" in capsys.readouterr().err
    assert main([str(tmp_path / "other"), "--window", "10:12"]) == 0
    assert "up->down" in capsys.readouterr().out
