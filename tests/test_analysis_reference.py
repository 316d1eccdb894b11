"""analysis.reference on a synthetic run folder written here without any engine (six snapshots of the demo case):
three snapshots are stored evenly in time with the last; droplets and the slag plane come back to float32
precision, the CSV files with whole numbers exact and other values to 7 significant digits (float32's precision);
reference.json says where the run came from and when it ended; an oversized reference keeps fewer snapshots and
says so, and one snapshot still too large keeps 15 mantissa bits or fewer (bit rounding, error within
2^-(bits+1)); a folder without its time series or case is refused; and the
command line stores a run (exit 0) or refuses a bad folder (exit 2)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pandas as pd
import pytest

from analysis import reference
from settler.cases import load_case
from settler.output import read_time_series, time_series_frame, write_channel_profile, write_time_series

ROOT = Path(__file__).resolve().parents[1]
TIMES = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0)  # [s]
BOX = 0.1  # the demo case's cube [m]; inlet centre y = 0.05 m, half-way between two layers of the 4-cell grid
CELLS = 4


def _droplets(seed, n):
    """``n`` droplets in the box: (points (n, 3) [m], point_data in SI units)."""
    rng = np.random.default_rng(seed)
    velocity = rng.normal(0.0, 2e-3, (n, 3))
    velocity[:, 2] = -rng.uniform(1e-3, 2e-2, n)
    data = {"diameter": rng.uniform(2e-4, 1.2e-3, n), "velocity": velocity,
            "density": rng.uniform(4500.0, 5200.0, n), "age": rng.uniform(0.0, 3.0, n),
            "ident": np.arange(n, dtype=float), "merged": (rng.random(n) < 0.3).astype(float)}
    return rng.uniform(0.01, 0.09, (n, 3)), data


def _write_fluid(path, scale):
    """A uniform hexahedral grid over the box; cell velocity = scale * (z - c, y, c - x) [m/s], c = the box centre
    (v = scale * y, so the mean of the two central layers is scale * 0.05)."""
    n = CELLS
    edges = np.linspace(0.0, BOX, n + 1)
    points = np.stack(np.meshgrid(edges, edges, edges, indexing="ij"), axis=-1).reshape(-1, 3)

    def node(i, j, k):
        return (i * (n + 1) + j) * (n + 1) + k

    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij"))
    cells = np.stack([node(i, j, k), node(i + 1, j, k), node(i + 1, j + 1, k), node(i, j + 1, k),
                      node(i, j, k + 1), node(i + 1, j, k + 1), node(i + 1, j + 1, k + 1), node(i, j + 1, k + 1)],
                     axis=1)
    centres = points[cells].mean(axis=1)
    c = 0.5 * BOX
    velocity = scale * np.stack([centres[:, 2] - c, centres[:, 1], c - centres[:, 0]], axis=1)
    mesh = meshio.Mesh(points, [("hexahedron", cells)],
                       cell_data={"velocity": [velocity], "pressure": [np.zeros(len(cells))],
                                  "void_fraction": [np.ones(len(cells))]})
    meshio.write(path, mesh, file_format="vtu", binary=True)


def _make_run(folder, n_droplets=30):
    """A synthetic full-engine run folder of the demo case; returns {snapshot index: (points, point_data)}."""
    folder.mkdir(parents=True)
    (folder / "case.toml").write_text(load_case("demo").to_toml())
    (folder / "metadata.json").write_text(json.dumps({"engine": "fulldem", "command": "settler full demo --out X"}))
    (folder / "summary.json").write_text(json.dumps({"settled_fraction": 0.25}))
    (folder / "checkpoint.npz").write_bytes(b"not copied")
    t = np.linspace(0.0, TIMES[-1], 31)
    rows = [{"time": ti, "droplet_count": 10 + 7 * ti, "mean_diameter": 5e-4 + 1e-4 * ti / 3.0,
             "mass_fed": 1e-3 * ti, "channel_radius": 0.02 - 0.004 * ti, "wall_time": 12.5 * ti} for ti in t]
    write_time_series(time_series_frame(rows), folder / "timeseries.csv")
    (folder / "merges_by_size.csv").write_text("bin,0,1\n0,3,1\n1,0,2\n")
    written, entries = {}, []
    for index, time in enumerate(TIMES):
        points, data = _droplets(index, n_droplets + index)
        mesh = meshio.Mesh(points, [("vertex", np.arange(len(points)).reshape(-1, 1))], point_data=data)
        meshio.write(folder / f"droplets_{index:05d}.vtu", mesh, file_format="vtu", binary=True, compression="zlib")
        _write_fluid(folder / f"fluid_{index:05d}.vtu", scale=0.1 * (index + 1))
        written[index] = (points, data)
        entries += [f'    <DataSet timestep="{time:.9g}" part="0" file="droplets_{index:05d}.vtu"/>',
                    f'    <DataSet timestep="{time:.9g}" part="1" file="fluid_{index:05d}.vtu"/>']
    (folder / "snapshots.pvd").write_text('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n'
                                          "  <Collection>\n" + "\n".join(entries) + "\n  </Collection>\n</VTKFile>\n")
    profile = [{"time": ti, "z": z, "channel_radius": 0.01 + 0.1 * z, "channel_velocity": 0.02 - 0.1 * z,
                "droplet_volume": 1e-9} for ti in TIMES for z in np.linspace(0.005, 0.095, 10)]
    write_channel_profile(profile, folder / "channel_profile.csv")
    return written


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    base = tmp_path_factory.mktemp("reference")
    written = _make_run(base / "run")
    dest = reference.store_reference(base / "run", "demo", dest_root=base / "refs", snapshots=3,
                                     command="settler full demo --out runs/demo", commit="0" * 40)
    return base, written, dest


def test_choose_snapshots_even_with_the_last():
    assert reference.choose_snapshots(TIMES, 3) == [1, 3, 5]
    assert reference.choose_snapshots(TIMES, 1) == [5]
    assert reference.choose_snapshots(TIMES, 6) == list(range(6))
    assert reference.choose_snapshots(TIMES, 10) == list(range(6))
    assert reference.choose_snapshots([], 4) == []
    # crowded early times: still distinct, in order, ending with the last
    chosen = reference.choose_snapshots([0.0, 0.1, 0.2, 0.3, 10.0], 4)
    assert chosen == sorted(set(chosen)) and len(chosen) == 4 and chosen[-1] == 4


def test_stored_folder_is_small_and_complete(stored):
    base, _, dest = stored
    assert dest == base / "refs" / "demo"
    names = {p.name for p in dest.iterdir()}
    assert names == {"timeseries.csv", "case.toml", "merges_by_size.csv", "channel_profile.csv", "snapshots.npz",
                     "reference.json"}
    assert not any(p.name.startswith(".") for p in (base / "refs").iterdir())  # no temporary folders left
    for name in ("timeseries.csv", "merges_by_size.csv", "channel_profile.csv"):
        _assert_float32_copy((dest / name).read_text(), (base / "run" / name).read_text())
    # case.toml: the same lines but the first, whose 'loaded from' names the case file from data/, not this machine
    stored_lines = (dest / "case.toml").read_text().splitlines()
    run_lines = (base / "run" / "case.toml").read_text().splitlines()
    assert stored_lines[1:] == run_lines[1:]
    assert stored_lines[0] == "# resolved case; loaded from data/cases/demo.toml", stored_lines[0]
    assert reference.available_references(base / "refs") == ["demo"]


def _assert_float32_copy(stored, original):
    """Comment and header lines alike; every field the same where it is not a number with a fraction, else
    within half a unit of the 7th significant digit."""
    a, b = stored.splitlines(), original.splitlines()
    assert len(a) == len(b)
    for x, y in zip(a, b):
        if y.startswith("#") or not any(c.isdigit() for c in y.split(",")[0]):
            assert x == y
            continue
        for fx, fy in zip(x.split(","), y.split(","), strict=True):
            try:
                value = float(fy)
            except ValueError:
                assert fx == fy
                continue
            if value == int(value) if np.isfinite(value) else True:
                assert fx == fy
            else:
                assert abs(float(fx) - value) <= 5e-7 * abs(value) and len(fx) <= len(fy)


def test_compact_table_keeps_counts_exact_and_seven_digits():
    """Counts past 1e7 stay exact (%.7g would round them); fractions keep 7 significant digits; empty fields,
    text and the units line stay as written."""
    text = "# units: t [s], n [-], x [m]\nt,n,x,label\n0.1,123456789.0,0.00012345678901234,a\n2.0,5.0,,b\n"
    compact = reference.compact_table(text)
    assert compact == "# units: t [s], n [-], x [m]\nt,n,x,label\n0.1,123456789.0,0.0001234568,a\n2.0,5.0,,b\n"
    _assert_float32_copy(compact, text)


def test_bit_round_error_bound_and_compression():
    """Bit rounding to 15 mantissa bits: relative error at most 2^-16, NaN kept, the 8 low bits zero, and random
    positions compress to about 3/4 of their float32 size or less."""
    rng = np.random.default_rng(5)
    values = rng.uniform(0.0, 0.55, 200_000).astype(np.float32)
    values[:3] = [np.nan, 0.0, -1.5]
    rounded = reference.bit_round(values, 15)
    assert np.isnan(rounded[0]) and rounded[1] == 0.0 and rounded[2] == -1.5
    finite = np.isfinite(values) & (values != 0)
    assert np.all(np.abs(rounded[finite] / values[finite] - 1.0) <= 2.0**-16)
    assert np.all(rounded[finite].view(np.uint32) & np.uint32(0xFF) == 0)
    import zlib

    assert len(zlib.compress(rounded.tobytes())) < 0.8 * len(zlib.compress(values.tobytes()))


def test_chosen_times_evenly_spread_with_the_last(stored):
    _, _, dest = stored
    ref = reference.load_reference("demo", dest.parent)
    np.testing.assert_array_equal(ref.snapshot_times, [1.0, 2.0, 3.0])
    assert ref.snapshot_times[-1] == TIMES[-1]
    assert np.allclose(np.diff(ref.snapshot_times), np.diff(ref.snapshot_times)[0])
    assert ref.info["snapshots"]["times"] == [1.0, 2.0, 3.0]


def test_droplets_equal_originals_to_float32(stored):
    _, written, dest = stored
    ref = reference.load_reference("demo", dest.parent)
    for k, index in enumerate((1, 3, 5)):
        points, data = written[index]
        for key in (k, TIMES[index]):  # by index and by time
            frame = ref.droplets(key)
            assert list(frame.columns[:10]) == ["x", "y", "z", "diameter", "u", "v", "w", "density", "age", "merged"]
            assert len(frame) == len(points)
            f32 = lambda a: np.asarray(a, dtype=np.float32).astype(float)  # noqa: E731
            np.testing.assert_array_equal(frame[["x", "y", "z"]].to_numpy(), f32(points))
            np.testing.assert_array_equal(frame[["u", "v", "w"]].to_numpy(), f32(data["velocity"]))
            for name in ("diameter", "density", "age", "merged"):
                np.testing.assert_array_equal(frame[name].to_numpy(), f32(data[name]))
            np.testing.assert_allclose(frame["diameter"], data["diameter"], rtol=1e-7)
            np.testing.assert_array_equal(frame["settling_velocity"], -frame["w"])
    assert ref.droplets().equals(ref.droplets(2)) and ref.droplets(2.9).equals(ref.droplets(-1))
    with pytest.raises(IndexError):
        ref.droplets(3)
    with np.load(dest / "snapshots.npz") as npz:
        assert npz["times"].dtype == np.float64
        assert all(npz[k].dtype == np.float32 for k in npz.files if k not in ("times",) and not k.endswith("_y"))


def test_slag_plane_is_the_mean_of_the_two_central_layers(stored):
    _, _, dest = stored
    ref = reference.load_reference("demo", dest.parent)
    h = BOX / CELLS
    centres = (np.arange(CELLS) + 0.5) * h
    for k, index in enumerate((1, 3, 5)):
        x, z, velocity = ref.slag(k)
        assert len(x) == CELLS * CELLS and velocity.shape == (CELLS * CELLS, 3)
        np.testing.assert_allclose(x, np.tile(centres, CELLS), rtol=1e-6)  # sorted by z, then x
        np.testing.assert_allclose(z, np.repeat(centres, CELLS), rtol=1e-6)
        scale = 0.1 * (index + 1)
        np.testing.assert_allclose(velocity[:, 0], scale * (z - 0.05), rtol=1e-5, atol=1e-8)
        np.testing.assert_allclose(velocity[:, 1], scale * 0.05, rtol=1e-6)  # (v at 0.0375 + at 0.0625) / 2
        np.testing.assert_allclose(velocity[:, 2], scale * (0.05 - x), rtol=1e-5, atol=1e-8)
        assert ref.slag_plane_y(k) == pytest.approx(0.05)
        speed = np.hypot(velocity[:, 0], velocity[:, 2]).reshape(CELLS, CELLS)  # rows z, columns x
        assert speed.shape == (CELLS, CELLS)


def test_time_series_case_and_csvs_round_trip(stored):
    base, _, dest = stored
    ref = reference.load_reference("demo", dest.parent)
    pd.testing.assert_frame_equal(ref.timeseries, read_time_series(base / "run" / "timeseries.csv"),
                                  check_exact=False, rtol=5e-7, atol=0.0)
    assert ref.case.to_dict() == load_case(base / "run" / "case.toml").to_dict()
    assert ref.case.case.name == "demo" and ref.case.inlet_center == (0.05, 0.05)
    assert ref.merges_by_size is not None and ref.merges_by_size.shape == (2, 3)
    assert ref.channel_profile is not None and sorted(ref.channel_profile["time"].unique()) == list(TIMES)


def test_reference_json(stored):
    base, _, dest = stored
    info = json.loads((dest / "reference.json").read_text())
    assert info["case_name"] == "demo"
    assert "source" not in info and str(base) not in json.dumps(info)  # provenance names no folder of this machine
    assert info["seed"] == load_case(base / "run" / "case.toml").feed.seed
    assert info["command"] == "settler full demo --out runs/demo" and info["commit"] == "0" * 40
    assert info["end_time"] == 3.0 and info["wall_time"] == 37.5
    assert info["droplets_at_end"] == 31
    assert info["metadata"]["engine"] == "fulldem" and info["summary"] == {"settled_fraction": 0.25}
    assert info["files"] == {p.name: p.stat().st_size for p in dest.iterdir() if p.name != "reference.json"}
    assert "float32" in info["precision"] and info["notes"] == []


def test_defaults_command_from_metadata_and_commit_from_git(tmp_path):
    _make_run(tmp_path / "run", n_droplets=5)
    dest = reference.store_reference(tmp_path / "run", "demo", dest_root=tmp_path / "refs", snapshots=2)
    info = json.loads((dest / "reference.json").read_text())
    assert info["command"] == "settler full demo --out X"
    assert "commit" in info and (info["commit"] is None or len(info["commit"]) == 40)
    assert info["snapshots"]["times"] == [1.5, 3.0]
    # storing again replaces the folder's content
    (dest / "stray.txt").write_text("old")
    reference.store_reference(tmp_path / "run", "demo", dest_root=tmp_path / "refs", snapshots=1)
    assert not (dest / "stray.txt").exists()
    assert reference.load_reference("demo", tmp_path / "refs").snapshot_times.tolist() == [3.0]
    assert [p.name for p in (tmp_path / "refs").iterdir()] == ["demo"]


def test_too_large_keeps_fewer_snapshots_and_says_so(tmp_path, monkeypatch):
    _make_run(tmp_path / "run", n_droplets=400)
    one = reference.store_reference(tmp_path / "run", "one", dest_root=tmp_path / "refs", snapshots=1)
    size_one = sum(p.stat().st_size for p in one.iterdir())
    monkeypatch.setattr(reference, "SIZE_LIMIT", size_one + 2000)  # room for one snapshot, not for four
    dest = reference.store_reference(tmp_path / "run", "big", dest_root=tmp_path / "refs", snapshots=4)
    info = json.loads((dest / "reference.json").read_text())
    assert info["snapshots"]["requested"] == 4
    assert 1 <= info["snapshots"]["stored"] < 4
    assert info["snapshots"]["times"][-1] == 3.0
    assert any("limit" in note for note in info["notes"])
    assert sum(p.stat().st_size for p in dest.iterdir()) <= reference.SIZE_LIMIT
    monkeypatch.setattr(reference, "SIZE_LIMIT", 100)  # nothing fits: one snapshot, and a note that it is over
    dest = reference.store_reference(tmp_path / "run", "tiny", dest_root=tmp_path / "refs", snapshots=3)
    info = json.loads((dest / "reference.json").read_text())
    assert info["snapshots"]["stored"] == 1 and info["snapshots"]["times"] == [3.0]
    assert any("even with 1" in note for note in info["notes"])
    # one snapshot over the limit: droplets bit-rounded, 15 mantissa bits and fewer down to 12 while still over;
    # within 2^-(bits + 1) of the full one's; the same slag plane
    bits = [int(note.split(" keep ")[1].split()[0]) for note in info["notes"] if "mantissa bits" in note]
    assert bits == [reference.MIN_KEEP_BITS]
    refs = tmp_path / "refs"
    full, rounded = reference.load_reference("one", refs), reference.load_reference("tiny", refs)
    a, b = full.droplets(-1), rounded.droplets(-1)
    for column in ("x", "y", "z", "u", "v", "w", "diameter", "density", "age"):
        assert np.all(np.abs(b[column] - a[column]) <= 2.0 ** -(bits[0] + 1) * np.abs(a[column])), column
    assert (b["merged"] == a["merged"]).all() and not b["x"].equals(a["x"])
    np.testing.assert_array_equal(rounded.slag(-1)[2], full.slag(-1)[2])


@pytest.mark.parametrize("missing", ["timeseries.csv", "case.toml"])
def test_refuses_a_folder_without_series_or_case(tmp_path, missing):
    _make_run(tmp_path / "run", n_droplets=3)
    (tmp_path / "run" / missing).unlink()
    with pytest.raises(ValueError, match=missing):
        reference.store_reference(tmp_path / "run", "demo", dest_root=tmp_path / "refs")
    assert not (tmp_path / "refs" / "demo").exists()
    with pytest.raises(ValueError, match="no such run folder"):
        reference.store_reference(tmp_path / "nothing", "demo", dest_root=tmp_path / "refs")
    with pytest.raises(ValueError, match="case name"):
        reference.store_reference(tmp_path / "run", "../x", dest_root=tmp_path / "refs")


def _cli(*args):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "analysis.reference", *map(str, args)], capture_output=True,
                          text=True, env=env, cwd=ROOT, timeout=120)


def test_command_line(stored, tmp_path):
    base, _, _ = stored
    done = _cli(base / "run", "demo", "--dest", tmp_path / "refs", "--snapshots", "2")
    assert done.returncode == 0, done.stderr
    assert str(tmp_path / "refs" / "demo") in done.stdout and "MB" in done.stdout
    assert reference.load_reference("demo", tmp_path / "refs").snapshot_times.tolist() == [1.5, 3.0]
    bad = _cli(tmp_path / "nothing", "demo", "--dest", tmp_path / "refs")
    assert bad.returncode == 2
    assert "nothing" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1
    empty = tmp_path / "empty"
    empty.mkdir()
    bad = _cli(empty, "demo", "--dest", tmp_path / "refs")
    assert bad.returncode == 2 and "timeseries.csv" in bad.stderr


def test_figures_draw_from_a_stored_reference(stored, tmp_path):
    """`settler figures` on a data/reference/<case> folder: the snapshot figures come from its float32 snapshots
    (the same droplets as the run's last snapshot, to float32), none of them is skipped."""
    from analysis import figures

    folder = stored[2]
    written = figures.render_all(folder, tmp_path / "figs")
    snapshot_figures = ("slice_diameter", "slice_velocity", "slice_slag", "density_height", "velocity_height")
    skipped = {name: written[name] for name in snapshot_figures if not isinstance(written[name], Path)}
    assert not skipped, skipped
    t, frame = figures.read_droplets(folder)
    ref = reference.load_reference(Path(folder).name, Path(folder).parent)
    assert t == ref.snapshot_times[-1] and len(frame) == len(ref.droplets(-1))
