"""fulldem.io: progress display, snapshots that meshio reads back, and checkpoint errors."""

import io
import re
import time
from pathlib import Path

import meshio
import numpy as np
import pytest

from fulldem.droplets import DropletStore
from fulldem.fluid.grid import Grid
from fulldem.fluid.solver import FluidState
from fulldem.io import progress as fio_progress
from fulldem.io import snapshots as fio_snapshots
from fulldem.io.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from fulldem.io.progress import Progress
from fulldem.io.snapshots import SnapshotWriter, cell_centre_velocity
from settler.vti import read_image


pytest.importorskip("tqdm")


class FakeTTY(io.StringIO):
    def isatty(self):
        return True


def _pieces(text):
    """What a terminal shows in turn: the output split at carriage returns and newlines."""
    return [p for p in re.split(r"[\r\n]", text) if p]


PLAIN = re.compile(r"^t = +[0-9.]+ / 1 s \( *[0-9.]+ %\)  droplets +\d+  wall +[0-9.]+ s  ETA +(nan|[0-9.]+) s  ")


def test_progress_plain_lines_one_per_interval():
    stream = io.StringIO()
    bar = Progress(0.0, 1.0, interval=0.05, stream=stream)
    assert not bar.is_bar
    updates = 0
    start = time.perf_counter()
    for i in range(1, 101):
        bar.update(i / 100, 10 * i, "Re_cell 3.2")
        updates += 1
        time.sleep(0.004)
    elapsed = time.perf_counter() - start
    bar.close()
    text = stream.getvalue()
    assert "\r" not in text and text.endswith("\n")
    lines = text.splitlines()
    assert all(PLAIN.match(line) and line.endswith("Re_cell 3.2") for line in lines)
    # one line per interval, plus the final state shown by close()
    assert 2 <= len(lines) <= elapsed / 0.05 + 2
    assert len(lines) < updates / 4
    assert lines[-1].startswith("t =    1.000 / 1 s (100.0 %)  droplets     1000")


def test_progress_plain_close_with_final_time_and_no_duplicate():
    stream = io.StringIO()
    bar = Progress(0.0, 2.0, interval=100.0, stream=stream)
    bar.update(0.5, 7)  # the first report is printed
    bar.update(1.0, 8)  # within the interval: recorded only
    bar.close(t=2.0)
    lines = stream.getvalue().splitlines()
    assert len(lines) == 2
    assert lines[1].startswith("t =    2.000 / 2 s (100.0 %)  droplets        8")
    bar.close()  # idempotent
    assert len(stream.getvalue().splitlines()) == 2

    stream = io.StringIO()
    bar = Progress(0.0, 2.0, interval=100.0, stream=stream)
    bar.update(0.5, 7)
    bar.update(2.0, 9, force=True)
    bar.close()
    assert len(stream.getvalue().splitlines()) == 2  # close does not repeat a state already printed


def test_progress_disabled_writes_nothing():
    for stream in (io.StringIO(), FakeTTY()):
        bar = Progress(0.0, 1.0, enabled=False, stream=stream)
        bar.update(0.5, 3, force=True)
        bar.close(t=1.0)
        assert stream.getvalue() == ""


@pytest.mark.parametrize("ncols", [60, 100])
def test_progress_tty_is_a_tqdm_bar_that_fits_and_ends_at_100(ncols):
    stream = FakeTTY()
    bar = Progress(0.0, 1.0, interval=1.0, stream=stream, ncols=ncols)
    assert bar.is_bar
    extra = "Re_cell 123  CFL 0.21  overlap 0.0113"
    for i in range(1, 51):
        bar.update(i / 50, 1000 + i, extra)
        time.sleep(0.01)
    bar.close()
    text = stream.getvalue()
    assert " " * 150 not in text
    pieces = _pieces(text)
    assert pieces and all(len(p) <= ncols for p in pieces)
    assert "%|" in pieces[-1]  # tqdm's bar, not the plain line
    assert not any(PLAIN.match(p) for p in pieces)
    assert "100%" in pieces[-1] and "t = 1.000/1 s" in pieces[-1]
    assert "droplets 1050" in pieces[-1] or ncols < 100
    assert text.endswith("\n")


def test_progress_tty_close_at_final_time_reaches_100():
    stream = FakeTTY()
    bar = Progress(2.0, 4.0, stream=stream, ncols=120)
    bar.update(2.5, 10, "x")
    bar.update(3.9999999999, 12, "y")  # the run's last step, t_end to round-off; not shown yet (interval)
    bar.close()
    last = _pieces(stream.getvalue())[-1]
    assert "100%" in last and "droplets 12  y" in last

    stream = FakeTTY()
    bar = Progress(0.0, 4.0, stream=stream, ncols=120)
    bar.update(1.0, 10)
    bar.close(t=4.0)
    assert "100%" in _pieces(stream.getvalue())[-1]

    stream = FakeTTY()  # a run stopped early stays where it stopped
    bar = Progress(0.0, 4.0, stream=stream, ncols=120)
    bar.update(1.0, 10, force=True)
    bar.close()
    last = _pieces(stream.getvalue())[-1]
    assert " 25%" in last and "100%" not in last

    stream = FakeTTY()  # resumed at its end time: nothing left to do, and done
    bar = Progress(4.0, 4.0, stream=stream, ncols=120)
    bar.close(t=4.0)
    assert "100%" in _pieces(stream.getvalue())[-1]


def test_progress_first_update_does_not_count_towards_the_rate():
    stream = FakeTTY()
    bar = Progress(0.0, 10.0, stream=stream, ncols=120)
    time.sleep(0.3)  # "compilation" in the first step
    bar.update(0.01, 1, force=True)
    assert bar._bar.initial == pytest.approx(0.01)  # the rate is counted from here
    assert "<?" in _pieces(stream.getvalue())[-1]  # no remaining time from the first step's pace
    bar.close()


def test_progress_notebook_uses_a_bar(monkeypatch):
    monkeypatch.setattr(fio_progress, "_in_notebook", lambda: True)
    stream = io.StringIO()
    monkeypatch.setattr("sys.stderr", stream)
    bar = Progress(0.0, 1.0)
    assert bar.is_bar
    bar.update(1.0, 5, force=True)
    bar.close()
    assert Progress(0.0, 1.0, stream=io.StringIO()).is_bar is False  # an explicit file stream: plain lines


def _store(n):
    store = DropletStore()
    if n:
        rng = np.random.default_rng(1)
        store.add(rng.uniform(0.0, 0.01, (n, 3)), np.array([1e-4, 2e-4, 5e-4])[:n], 5000.0,
                  velocity=rng.normal(size=(n, 3)))
    return store


def test_slag_image_data_holds_each_cell_where_vtk_puts_it(tmp_path):
    """fluid_NNNNN.vti: cell (i, j, k) of our (nx, ny, nz) arrays is VTK's cell i + nx (j + ny k), its value and
    its place; read back by settler.vti and, where the vtk package is installed, by VTK's own reader."""
    grid = Grid((3, 4, 5), 0.01, lower=(0.1, 0.2, 0.3))
    rng = np.random.default_rng(3)
    fluid = FluidState(*(rng.normal(size=a.shape) for a in grid.zeros_faces()), rng.normal(size=grid.shape))
    phi = rng.uniform(0.5, 1.0, grid.shape)
    SnapshotWriter(tmp_path, grid).write(0.0, _store(0), fluid, phi)
    path = tmp_path / "fluid_00000.vti"
    shape, origin, spacing, fields = read_image(path)
    centre = cell_centre_velocity(grid, fluid.u, fluid.v, fluid.w)
    np.testing.assert_array_equal(fields["velocity"], centre.astype(np.float32))
    np.testing.assert_array_equal(fields["pressure"], fluid.p.astype(np.float32))
    np.testing.assert_array_equal(fields["void_fraction"], phi.astype(np.float32))
    np.testing.assert_allclose(origin, grid.lower)
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    reader = vtk.vtkXMLImageDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    image = reader.GetOutput()
    assert image.GetDimensions() == (4, 5, 6) and image.GetSpacing() == (0.01, 0.01, 0.01)
    velocity = vtk_to_numpy(image.GetCellData().GetArray("velocity"))
    for i, j, k in [(0, 0, 0), (2, 1, 3), (1, 3, 4)]:
        cell = i + 3 * (j + 4 * k)
        np.testing.assert_array_equal(velocity[cell], centre[i, j, k].astype(np.float32))
        bounds = image.GetCell(cell).GetBounds()
        np.testing.assert_allclose(bounds[::2], np.asarray(grid.lower) + 0.01 * np.array([i, j, k]), atol=1e-12)


def test_snapshots_read_back_with_meshio(tmp_path):
    grid = Grid((2, 3, 4), 0.0025)
    fluid = FluidState(*grid.zeros_faces(), grid.zeros_cells())
    writer = SnapshotWriter(tmp_path, grid)
    empty, three = _store(0), _store(3)
    writer.write(0.0, empty, fluid, np.ones(grid.shape))
    writer.write(0.5, three, fluid, np.ones(grid.shape))

    m0 = meshio.read(tmp_path / "droplets_00000.vtu")
    assert m0.points.shape == (0, 3)
    assert m0.point_data["diameter"].shape == (0,)
    assert m0.point_data["velocity"].shape == (0, 3)
    assert set(m0.point_data) == {"diameter", "velocity", "density", "age", "ident", "merged"}

    m3 = meshio.read(tmp_path / "droplets_00001.vtu")
    assert m3.points.shape == (3, 3)
    np.testing.assert_array_equal(m3.points, three.position[:3])
    np.testing.assert_array_equal(m3.point_data["diameter"], [1e-4, 2e-4, 5e-4])
    np.testing.assert_array_equal(m3.point_data["velocity"], three.velocity[:3])
    assert [c.type for c in m3.cells] == ["vertex"] and len(m3.cells[0]) == 3

    for index in (0, 1):
        shape, origin, spacing, fields = read_image(tmp_path / f"fluid_{index:05d}.vti")
        assert shape == (2, 3, 4) and spacing == 0.0025 and set(fields) == {"velocity", "pressure", "void_fraction"}
        assert fields["velocity"].shape == (2, 3, 4, 3) and np.all(fields["void_fraction"] == 1.0)
    pvd = (tmp_path / "snapshots.pvd").read_text()
    assert pvd.count("<DataSet") == 4 and 'timestep="0.5"' in pvd


def test_mesh_bytes_removes_its_temporary_file_on_failure(tmp_path, monkeypatch):
    made = []
    real_mkstemp = fio_snapshots.tempfile.mkstemp

    def mkstemp(*args, **kwargs):
        fd, name = real_mkstemp(*args, dir=tmp_path, **kwargs)
        made.append(name)
        return fd, name

    def broken_write(filename, *args, **kwargs):
        with open(filename, "wb") as fh:
            fh.write(b"partial")
        raise RuntimeError("disk full")

    monkeypatch.setattr(fio_snapshots.tempfile, "mkstemp", mkstemp)
    monkeypatch.setattr(fio_snapshots.meshio, "write", broken_write)
    with pytest.raises(RuntimeError, match="disk full"):
        fio_snapshots._mesh_bytes(meshio.Mesh(np.zeros((1, 3)), [("vertex", np.zeros((1, 1), dtype=int))]))
    assert made and not any(Path(p).exists() for p in made)


def _checkpoint(tmp_path):
    path = tmp_path / "checkpoint.npz"
    save_checkpoint(path, {"position": np.arange(30000.0).reshape(-1, 3), "count": np.int64(7)},
                    {"time": 1.5, "steps": np.int64(3)})
    return path


def test_checkpoint_round_trip(tmp_path):
    arrays, meta = load_checkpoint(_checkpoint(tmp_path))
    assert meta == {"time": 1.5, "steps": 3}
    np.testing.assert_array_equal(arrays["position"], np.arange(30000.0).reshape(-1, 3))


@pytest.mark.parametrize("keep", [0.3, 0.9, 0.999])
def test_truncated_checkpoint_raises_checkpoint_error(tmp_path, keep):
    path = _checkpoint(tmp_path)
    data = path.read_bytes()
    path.write_bytes(data[: int(keep * len(data))])
    with pytest.raises(CheckpointError, match="is truncated or not a checkpoint written by settler full: ") as info:
        load_checkpoint(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)
    assert isinstance(info.value, ValueError)


def test_not_an_npz_raises_checkpoint_error(tmp_path):
    for name, content in [("text.npz", b"time = 1.5\n" * 10), ("empty.npz", b"")]:
        path = tmp_path / name
        path.write_bytes(content)
        with pytest.raises(CheckpointError, match=f"{name} is truncated or not a checkpoint") as info:
            load_checkpoint(path)
        assert "\n" not in str(info.value)
    path = tmp_path / "array.npy"
    np.save(path, np.arange(3))
    with pytest.raises(CheckpointError, match="not an .npz archive"):
        load_checkpoint(path)


def test_npz_without_meta_raises_checkpoint_error(tmp_path):
    path = tmp_path / "other.npz"
    np.savez(path, position=np.zeros((2, 3)))
    with pytest.raises(CheckpointError, match="other.npz is truncated or not a checkpoint written by settler "
                                              "full: no __meta__ entry"):
        load_checkpoint(path)
    np.savez(path, __meta__=np.frombuffer(b"{not json", dtype=np.uint8))
    with pytest.raises(CheckpointError, match="__meta__ is not JSON"):
        load_checkpoint(path)


def test_missing_checkpoint_is_still_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_checkpoint(tmp_path / "nothing.npz")
