"""analysis.figures on a synthetic run folder written here without any engine: every figure renders, the readers
give back exactly what was written, the slab of the slice figures keeps exactly the droplets inside it, missing
inputs skip a figure with a reason, and ``settler figures`` writes the PNGs (exit 0) or refuses a non-run (exit 2)."""

import os
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

from analysis import figures
from settler.cases import load_case
from settler.output import (LIFT_BY_SIZE, ZONE_PROFILE, ZONES, time_series_frame, write_channel_profile,
                            write_table, write_time_series)


ROOT = Path(__file__).resolve().parents[1]
TIMES = (1.0, 2.0)
N_DROPLETS = 40


def _droplets(seed):
    """A few dozen droplets in the demo's 0.1 m box: (points (n, 3) [m], point_data in SI units)."""
    rng = np.random.default_rng(seed)
    n = N_DROPLETS
    diameter = rng.uniform(2e-4, 1.2e-3, n)
    points = rng.uniform(0.01, 0.09, (n, 3))
    velocity = rng.normal(0.0, 2e-3, (n, 3))
    velocity[:, 2] = -rng.uniform(1e-3, 2e-2, n)
    data = {"diameter": diameter, "velocity": velocity, "density": rng.uniform(4500.0, 5200.0, n),
            "age": rng.uniform(0.0, 2.0, n), "ident": np.arange(n, dtype=float),
            "merged": (rng.random(n) < 0.3).astype(float)}
    return points, data


def _write_droplets(path, points, data):
    n = len(points)
    if n:
        mesh = meshio.Mesh(points, [("vertex", np.arange(n).reshape(-1, 1))], point_data=data)
        meshio.write(path, mesh, file_format="vtu", binary=True, compression="zlib")
    else:  # as the engine writes an empty snapshot (fulldem/io/): zero points, one polygon of zero points
        data = {k: np.zeros((0, 3) if k == "velocity" else 0) for k in data}
        mesh = meshio.Mesh(np.zeros((0, 3)), [("polygon", np.zeros((1, 0), dtype=np.int64))], point_data=data)
        meshio.write(path, mesh, file_format="vtu", binary=True, compression=None)


def _write_fluid(path, cells_per_side=4, size=0.1):
    """A uniform hexahedral grid over the box with a swirl in the x-z plane: cell velocity = (z - c, 0, c - x)."""
    n = cells_per_side
    edges = np.linspace(0.0, size, n + 1)
    points = np.stack(np.meshgrid(edges, edges, edges, indexing="ij"), axis=-1).reshape(-1, 3)

    def node(i, j, k):
        return (i * (n + 1) + j) * (n + 1) + k

    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij"))
    cells = np.stack([node(i, j, k), node(i + 1, j, k), node(i + 1, j + 1, k), node(i, j + 1, k),
                      node(i, j, k + 1), node(i + 1, j, k + 1), node(i + 1, j + 1, k + 1), node(i, j + 1, k + 1)],
                     axis=1)
    centres = points[cells].mean(axis=1)
    c = 0.5 * size
    velocity = np.stack([centres[:, 2] - c, np.zeros(len(centres)), c - centres[:, 0]], axis=1) * 0.1
    mesh = meshio.Mesh(points, [("hexahedron", cells)],
                       cell_data={"velocity": [velocity], "pressure": [np.zeros(len(cells))],
                                  "void_fraction": [np.ones(len(cells))]})
    meshio.write(path, mesh, file_format="vtu", binary=True)
    return centres, velocity


def _write_pvd(folder, times):
    rows = []
    for index, t in enumerate(times):
        rows.append(f'    <DataSet timestep="{t:.9g}" part="0" file="droplets_{index:05d}.vtu"/>')
        rows.append(f'    <DataSet timestep="{t:.9g}" part="1" file="fluid_{index:05d}.vtu"/>')
    (folder / "snapshots.pvd").write_text('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n'
                                          "  <Collection>\n" + "\n".join(rows) + "\n  </Collection>\n</VTKFile>\n")


def _write_series(folder):
    t = np.linspace(0.0, TIMES[-1], 21)
    rows = [{"time": ti, "droplet_count": 10 + 15 * ti, "coalesced_count": 4 * ti, "uncoalesced_count": 10 + 11 * ti,
             "merges": 1.0, "mean_diameter": 5e-4 + 1e-4 * ti, "sauter_diameter": 6e-4 + 1e-4 * ti,
             "mean_settling_velocity": 5e-3 + 1e-3 * ti,
             "centreline_settling_velocity": np.nan if ti < 0.5 else 8e-3 + 2e-3 * ti,
             "channel_radius": 0.02 - 0.004 * ti, "channel_velocity": 0.01 * ti} for ti in t]
    write_time_series(time_series_frame(rows), folder / "timeseries.csv")


def _make_run(folder, snapshots=True, empty_last=False):
    """A synthetic run folder of the demo case; returns {time: (points, point_data)} of its droplet snapshots."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "case.toml").write_text(load_case("demo").to_toml())
    _write_series(folder)
    written = {}
    if snapshots:
        for index, t in enumerate(TIMES):
            points, data = _droplets(index)
            if empty_last and index == len(TIMES) - 1:
                points, data = np.zeros((0, 3)), data
            _write_droplets(folder / f"droplets_{index:05d}.vtu", points, data)
            _write_fluid(folder / f"fluid_{index:05d}.vtu")
            written[t] = (points, data)
        _write_pvd(folder, TIMES)
        profile = [{"time": t, "z": z, "channel_radius": 0.01 + 0.1 * z, "channel_velocity": 0.02 - 0.1 * z,
                    "droplet_volume": 1e-9} for t in TIMES for z in np.linspace(0.005, 0.095, 10)]
        write_channel_profile(profile, folder / "channel_profile.csv")
        zone = [{"time": t, "z": z, "volume_fraction": 0.01, "core_volume_fraction": 0.05, "upward_slag_flux": 1e-6,
                 "downward_slag_flux": 1.1e-6, "return_radius": 0.02 + 0.1 * z, "rising_volume": 1e-10}
                for t in TIMES for z in np.linspace(0.005, 0.095, 10)]
        write_table(zone, ZONE_PROFILE, folder / "zone_profile.csv")
        write_table([{"time": t, "roof_thickness": 0.005, "roof_volume_fraction": 0.1, "roof_peak_fraction": 0.12,
                      "rising_count": 3, "rising_volume": 1e-10} for t in TIMES], ZONES, folder / "zones.csv")
        write_table([{"time": t, "diameter_low": lo, "diameter_high": lo * 2 ** (1 / 3), "count": 10,
                      "rising_count": 2, "rising_velocity": 1e-3} for t in TIMES for lo in (4e-4, 5e-4)],
                    LIFT_BY_SIZE, folder / "lift_by_size.csv")
    return written


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("figures") / "run"
    return folder, _make_run(folder)


def _is_png(path):
    path = Path(path)
    return path.is_file() and path.stat().st_size > 1000 and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_every_figure_renders(run, tmp_path):
    folder, _ = run
    results = figures.render_all(folder, tmp_path / "png")
    assert set(results) == set(figures.FIGURE_FILES)
    for name, path in results.items():
        assert isinstance(path, Path), f"{name} skipped: {path}"
        assert path.name == figures.FIGURE_FILES[name]
        assert _is_png(path)


def test_snapshot_files_in_time_order(run):
    folder, _ = run
    snapshots = figures.snapshot_files(folder)
    assert [t for t, _, _ in snapshots] == list(TIMES)
    assert [(d.name, f.name) for _, d, f in snapshots] == [("droplets_00000.vtu", "fluid_00000.vtu"),
                                                           ("droplets_00001.vtu", "fluid_00001.vtu")]


@pytest.mark.parametrize("requested, expected", [(None, 2.0), (1.0, 1.0), (1.2, 1.0), (1.9, 2.0), (50.0, 2.0)])
def test_read_droplets_exact_values(run, requested, expected):
    folder, written = run
    t, frame = figures.read_droplets(folder, requested)
    assert t == expected
    points, data = written[expected]
    np.testing.assert_array_equal(frame[["x", "y", "z"]].to_numpy(), points)
    np.testing.assert_array_equal(frame["diameter"], data["diameter"])
    np.testing.assert_array_equal(frame[["u", "v", "w"]].to_numpy(), data["velocity"])
    np.testing.assert_array_equal(frame["settling_velocity"], -data["velocity"][:, 2])
    for column in ("density", "age", "ident", "merged"):
        np.testing.assert_array_equal(frame[column], data[column])


def test_read_slag_centres_and_velocity(run):
    folder, _ = run
    t, centres, velocity = figures.read_slag(folder, 1.0)
    assert t == 1.0 and centres.shape == velocity.shape == (64, 3)
    np.testing.assert_allclose(np.unique(np.round(centres[:, 0], 12)), [0.0125, 0.0375, 0.0625, 0.0875])
    np.testing.assert_allclose(velocity[:, 0], 0.1 * (centres[:, 2] - 0.05), atol=1e-15)


def test_slab_keeps_exactly_the_droplets_inside(tmp_path):
    folder = tmp_path / "run"
    _make_run(folder)
    # add two marked droplets at x = 0.02 and 0.08 m: one just inside the slab around y = 0.05 m, one just outside
    points, data = _droplets(0)
    extra_d = np.array([5e-4, 5e-4])
    diameters = np.concatenate([data["diameter"], extra_d])
    half = figures.slab_half_thickness(diameters, 0.1)
    assert half == max(2 * diameters.mean(), 0.002)
    extra = np.array([[0.02, 0.05 + 0.999 * half, 0.05], [0.08, 0.05 - 1.001 * half, 0.05]])
    points = np.concatenate([points, extra])
    data = {k: np.concatenate([v, v[:2]]) for k, v in data.items()}
    data["diameter"] = diameters
    _write_droplets(folder / "droplets_00001.vtu", points, data)

    fig = figures.slice_droplets(folder, quantity="diameter")
    drawn = fig.axes[0].collections[0].get_offsets()
    inside = np.abs(points[:, 1] - 0.05) <= half
    assert inside[-2] and not inside[-1]
    assert len(drawn) == inside.sum()
    np.testing.assert_allclose(np.asarray(drawn), 1e3 * points[inside][:, [0, 2]])
    assert [20.0, 50.0] in np.asarray(drawn).tolist() and [80.0, 50.0] not in np.asarray(drawn).tolist()
    # coloured by downward speed: the same droplets, colours = -w in mm/s
    fig = figures.slice_droplets(folder, quantity="velocity")
    collection = fig.axes[0].collections[0]
    np.testing.assert_allclose(collection.get_array(), -1e3 * data["velocity"][inside, 2])


def test_slice_slag_draws_the_central_plane(run):
    folder, _ = run
    fig = figures.slice_slag(folder)
    mesh = fig.axes[0].collections[0]
    # 4 x 4 cells in x-z; y = 0.05 m lies between two layers, whose (equal) velocities are averaged
    speed = np.asarray(mesh.get_array()).reshape(4, 4)
    c = np.array([0.0125, 0.0375, 0.0625, 0.0875]) - 0.05
    expected = 1e3 * 0.1 * np.hypot(c[:, None], c[None, :])
    np.testing.assert_allclose(speed, expected, rtol=1e-12)


def test_empty_snapshot_skips_droplet_figures(tmp_path):
    folder = tmp_path / "run"
    _make_run(folder, empty_last=True)
    t, frame = figures.read_droplets(folder)
    assert t == 2.0 and frame.empty and "diameter" in frame
    results = figures.render_all(folder, tmp_path / "png")
    for name in ("slice_diameter", "slice_velocity", "density_height", "velocity_height"):
        assert isinstance(results[name], str) and "no droplets in the snapshot at t = 2 s" in results[name]
        assert "\n" not in results[name]
    for name in ("droplet_counts", "centre_diameter_velocity", "settling_velocity", "slice_slag", "channel"):
        assert _is_png(results[name]), results[name]
    # the earlier snapshot still has droplets
    assert _is_png(figures.render_all(folder, tmp_path / "png1", time=1.0)["slice_diameter"])


def test_run_without_snapshots_draws_the_time_series(tmp_path):
    folder = tmp_path / "run"
    _make_run(folder, snapshots=False)
    results = figures.render_all(folder, tmp_path / "png")
    for name in ("slice_diameter", "slice_velocity", "slice_slag", "density_height", "velocity_height"):
        assert results[name] == "no snapshots (no snapshots.pvd, or it lists none)"
    for name in ("droplet_counts", "centre_diameter_velocity", "settling_velocity", "channel"):
        assert _is_png(results[name]), results[name]
    with pytest.raises(figures.NoData, match="no snapshots"):
        figures.read_droplets(folder)


def test_not_a_run_is_refused(tmp_path):
    with pytest.raises(FileNotFoundError, match="no timeseries.csv and no snapshots.pvd") as info:
        figures.render_all(tmp_path, tmp_path / "png")
    assert str(tmp_path) in str(info.value)
    with pytest.raises(FileNotFoundError, match="no such run folder"):
        figures.snapshot_files(tmp_path / "missing")


def _settler(*args):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "settler", *map(str, args)], capture_output=True, text=True,
                          env=env, cwd=ROOT, timeout=120)


def test_cli_writes_the_figures(run, tmp_path):
    folder, _ = run
    out = tmp_path / "figs"
    done = _settler("figures", folder, "--out", out, "--time", "1.2")
    assert done.returncode == 0, done.stderr
    assert "the snapshot nearest --time 1.2" in done.stdout
    for name, file in figures.FIGURE_FILES.items():
        assert _is_png(out / file)
        assert f"{name}" in done.stdout and str(out / file) in done.stdout


def test_cli_refuses_a_folder_that_is_not_a_run(tmp_path):
    done = _settler("figures", tmp_path, "--out", tmp_path / "figs")
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("settler figures: error:") and str(tmp_path) in lines[0]
    assert not (tmp_path / "figs").exists()


# ------------------------------------------------------------------------- slag as image data (.vti) and as hexahedra
def test_slag_readers_take_image_data_and_older_hexahedra_alike(tmp_path):
    """analysis.files.slag_file and slag_plane read a .vti snapshot as they read the same grid's hexahedra (the
    .vtu of runs made before the image data)."""
    from settler.vti import image_bytes

    from analysis.files import slag_file, slag_plane

    n, size = 4, 0.1
    centres, velocity = _write_fluid(tmp_path / "fluid_00000.vtu", cells_per_side=n, size=size)
    (tmp_path / "fluid_00000.vti").write_bytes(image_bytes((n, n, n), (0.0, 0.0, 0.0), size / n,
                                                           {"velocity": velocity.reshape(n, n, n, 3)}))
    centres_i, velocity_i = slag_file(tmp_path / "fluid_00000.vti")
    centres_h, velocity_h = slag_file(tmp_path / "fluid_00000.vtu")
    np.testing.assert_allclose(centres_i, centres_h, atol=1e-15)
    np.testing.assert_allclose(velocity_i, velocity_h, rtol=1e-6)  # float32 in the .vti
    plane_i, plane_h = (slag_plane(tmp_path / f"fluid_00000.{s}", 0.05) for s in ("vti", "vtu"))
    assert plane_i.keys() == plane_h.keys() and plane_i["slag_y"] == pytest.approx(0.05)
    for key in plane_i:
        np.testing.assert_allclose(plane_i[key], plane_h[key], atol=1e-7)
