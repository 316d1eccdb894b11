"""Runs that survive interrupts and refuse what they cannot do: signals save a checkpoint and a resume reproduces the
uninterrupted run bit for bit; a checkpoint belongs to one case; an output folder holds one run; runs start without
droplets; a feed the inlet cannot take is reported (issue 10, "a new user's first hour")."""

import json
import math
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import fulldem.driver as fr
from fulldem.driver import RunError, RunInterrupted, run_case
from settler.cases import CaseError, load_case
from settler.output import read_time_series

# (the 2 ms step these end times are whole multiples of: a run ends at the first whole fluid step at or past its end)
SMALL = ["fulldem.cell_size=0.01", "fulldem.output_interval=0.02", "fulldem.snapshot_interval=0",
         "fulldem.checkpoint_interval=1000", "fulldem.fluid_step=0.002"]


def quiet(*args):
    pass


def _state(folder):
    """Every array of a run's final checkpoint."""
    with np.load(Path(folder) / "checkpoint.npz") as data:
        return {k: data[k] for k in data.files if k != "__meta__"}


def _assert_same_state(a, b):
    a, b = _state(a), _state(b)
    for name in ("droplet_position", "droplet_velocity", "droplet_ident", "u", "v", "w", "p", "owed_2"):
        assert a[name].shape == b[name].shape, name
        assert np.array_equal(a[name], b[name]), f"{name} differs by {np.abs(a[name] - b[name]).max()}"


@pytest.fixture(autouse=True)
def default_signal_handlers():
    """The tests send real signals: start from Python's default handlers even where the test process was started
    with SIGINT ignored (a background job), and put back what was there."""
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    yield
    for sig, handler in before.items():
        signal.signal(sig, handler)


def _interrupt_at(monkeypatch, step, signum):
    """Make the run receive ``signum`` right after its fluid step number ``step`` (a real signal, delivered to this
    process's handler)."""
    original = fr.Simulation.step

    def step_then_signal(self):
        out = original(self)
        if self.steps == step:
            signal.raise_signal(signum)
        return out

    monkeypatch.setattr(fr.Simulation, "step", step_then_signal)


@pytest.fixture(scope="module")
def straight(tmp_path_factory):
    """The demo case run straight to 0.3 s (150 fluid steps, about 1 600 droplets fed)."""
    out = tmp_path_factory.mktemp("straight")
    run_case(load_case("demo", SMALL), out, end_time=0.3, progress=False, log=quiet)
    return out


# Step 15 (t = 0.03 s) is a stop at which resuming from a checkpoint of 386d510 differed from the uninterrupted run
# (measured to t = 0.3 s: the neighbour list and its axis order were not saved, so the resumed run kept its droplets
# in another memory order and its fluid velocity differed at round-off, 1e-19 m/s; so did stops at 0.04 and 0.11 s);
# step 37 is a stop between two output rows.
@pytest.mark.parametrize("stop_step, signum", [(15, signal.SIGINT), (37, signal.SIGTERM)])
def test_signal_saves_and_resume_is_bitwise(straight, tmp_path, monkeypatch, stop_step, signum):
    case = load_case("demo", SMALL)
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    _interrupt_at(monkeypatch, stop_step, signum)
    with pytest.raises(RunInterrupted, match="--resume") as info:
        run_case(case, tmp_path, end_time=0.3, progress=False, log=quiet)
    assert info.value.signal_number == signum
    assert json.loads(bytes(np.load(tmp_path / "checkpoint.npz")["__meta__"]))["steps"] == stop_step
    monkeypatch.undo()
    assert {sig: signal.getsignal(sig) for sig in handlers} == handlers  # the run put the handlers back
    run_case(case, tmp_path, end_time=0.3, resume=True, progress=False, log=quiet)
    _assert_same_state(straight, tmp_path)
    a, b = read_time_series(straight / "timeseries.csv"), read_time_series(tmp_path / "timeseries.csv")
    assert a.drop(columns="wall_time").equals(b.drop(columns="wall_time"))


def test_sigterm_from_outside_exits_143_and_resumes(tmp_path):
    """The command line: SIGTERM (what a batch scheduler sends) saves, exits 128 + 15 with a line saying how to go
    on, and the resumed run ends where an uninterrupted one does."""
    args = [sys.executable, "-m", "settler.cli", "full", "demo", *SMALL, "--end-time", "0.4", "--quiet"]
    proc = subprocess.Popen(args + ["--out", str(tmp_path / "b")], stderr=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True)
    deadline = time.time() + 300
    while not (tmp_path / "b" / "timeseries.csv").exists() or \
            len((tmp_path / "b" / "timeseries.csv").read_text().splitlines()) < 4:  # a few steps in
        assert proc.poll() is None and time.time() < deadline, proc.communicate()
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert "SIGTERM" in err and "--resume" in err and "Traceback" not in err
    subprocess.run(args + ["--out", str(tmp_path / "b"), "--resume"], check=True, capture_output=True)
    subprocess.run(args + ["--out", str(tmp_path / "a")], check=True, capture_output=True)
    _assert_same_state(tmp_path / "a", tmp_path / "b")


def test_interrupt_before_any_output_row_still_resumes(tmp_path, monkeypatch):
    """An early Ctrl-C used to leave no checkpoint at all."""
    case = load_case("demo", SMALL)
    _interrupt_at(monkeypatch, 1, signal.SIGINT)
    with pytest.raises(RunInterrupted):
        run_case(case, tmp_path, end_time=0.01, progress=False, log=quiet)
    monkeypatch.undo()
    frame = run_case(case, tmp_path, end_time=0.01, resume=True, progress=False, log=quiet)
    assert frame["time"].iloc[-1] == pytest.approx(0.01)


# ------------------------------------------------------------------------------------------------ checkpoints
@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("short")
    run_case(load_case("demo", SMALL), out, end_time=0.02, progress=False, log=quiet)
    return out


@pytest.mark.parametrize("override, key", [("slag.viscosity_reference=0.5", "slag.viscosity_reference"),
                                           ("feed.seed=7", "feed.seed"),
                                           ("fulldem.cell_size=0.02", "fulldem.cell_size")])
def test_resume_with_another_case_is_refused_naming_the_keys(short_run, override, key):
    before = (short_run / "timeseries.csv").read_text()
    with pytest.raises(RunError, match=f"another case.*{key}: checkpoint"):
        run_case(load_case("demo", SMALL + [override]), short_run, end_time=0.04, resume=True, progress=False,
                 log=quiet)
    assert (short_run / "timeseries.csv").read_text() == before  # nothing was touched


def test_resume_may_change_run_control_keys(tmp_path):
    run_case(load_case("demo", SMALL), tmp_path, end_time=0.02, progress=False, log=quiet)
    frame = run_case(load_case("demo", SMALL + ["fulldem.end_time=5", "fulldem.checkpoint_interval=60"]), tmp_path,
                     end_time=0.03, resume=True, progress=False, log=quiet)
    assert frame["time"].iloc[-1] == pytest.approx(0.03)


def test_resume_end_time_not_after_checkpoint_is_refused(short_run):
    with pytest.raises(RunError, match="already at t = 0.02 s"):
        run_case(load_case("demo", SMALL), short_run, end_time=0.01, resume=True, progress=False, log=quiet)


def test_resume_with_droplets_is_refused(short_run, tmp_path):
    csv = tmp_path / "d.csv"
    csv.write_text("x,y,z,diameter\n0.05,0.05,0.05,0.001\n")
    with pytest.raises(RunError, match="--droplets with --resume"):
        run_case(load_case("demo", SMALL), short_run, end_time=0.04, resume=True, droplets=csv, progress=False,
                 log=quiet)


@pytest.mark.parametrize("content", [b"", b"not a zip at all", None])
def test_corrupt_checkpoint_is_one_line_through_the_cli(tmp_path, capsys, content):
    from settler.cli import main

    assert main(["full", "demo", *SMALL, "--out", str(tmp_path), "--end-time", "0.004", "--quiet"]) == 0
    path = tmp_path / "checkpoint.npz"
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2] if content is None else content)
    capsys.readouterr()
    assert main(["full", "demo", *SMALL, "--out", str(tmp_path), "--end-time", "0.01", "--resume", "--quiet"]) == 3
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "checkpoint.npz" in err and "truncated or not a checkpoint" in err


# ------------------------------------------------------------------------------------------------ output folders
def test_out_into_another_run_is_refused_unless_overwrite(short_run, tmp_path):
    with pytest.raises(RunError, match="holds another run.*--overwrite"):
        run_case(load_case("demo", SMALL), short_run, end_time=0.01, progress=False, log=quiet)
    out = tmp_path / "o"
    run_case(load_case("demo", SMALL + ["fulldem.snapshot_interval=0.004"]), out, end_time=0.012, progress=False,
             log=quiet)
    assert (out / "droplets_00003.vtu").exists()
    (out / "notes.txt").write_text("mine")
    run_case(load_case("demo", SMALL), out, end_time=0.004, progress=False, log=quiet, overwrite=True)
    assert not list(out.glob("droplets_*.vtu"))  # the other run's snapshots went with it ...
    assert (out / "notes.txt").read_text() == "mine"  # ... and nothing else


@pytest.mark.parametrize("out, expected", [("", "give the name of a folder"), ("file", "is a file"),
                                           ("file/sub", "part of the path is a file"), ("/dev/null", "is a file")])
def test_unusable_out_is_one_line(tmp_path, capsys, out, expected):
    from settler.cli import main

    (tmp_path / "file").write_text("x")
    out = out if out in ("", "/dev/null") else tmp_path / out
    assert main(["full", "demo", *SMALL, "--out", str(out), "--end-time", "0.004", "--quiet"]) == 2  # refused input
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and expected in err, err


def test_outputs_follow_the_umask(tmp_path):
    old = os.umask(0o022)
    try:
        run_case(load_case("demo", SMALL), tmp_path, end_time=0.004, progress=False, log=quiet)
    finally:
        os.umask(old)
    for name in ("case.toml", "metadata.json", "timeseries.csv", "checkpoint.npz", "summary.json"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o644, name


def test_metadata_is_strict_json(tmp_path):
    run_case(load_case("demo", SMALL + ["feed.mass_rate=0"]), tmp_path, end_time=0.004, progress=False, log=quiet)

    def refuse(token):
        raise ValueError(f"non-standard JSON constant {token}")

    for name in ("metadata.json", "summary.json"):
        json.loads((tmp_path / name).read_text(), parse_constant=refuse)


# ------------------------------------------------------------------------------------------------ starts
@pytest.mark.parametrize("overrides, feed, droplets", [
    ([], False, None),  # settler full demo --no-feed, no droplet list
    (["feed.mass_rate=0"], None, None),
    (["feed.mass_rate=1e-6"], None, None),  # a droplet every few fluid steps
    ([], False, "header"),  # a header-only droplet list
])
def test_runs_without_droplets_in_the_first_step(tmp_path, overrides, feed, droplets):
    path = None
    if droplets:
        path = tmp_path / "drops.csv"
        path.write_text("x,y,z,diameter\n")
    frame = run_case(load_case("demo", SMALL + overrides), tmp_path / "out", end_time=0.04, feed=feed,
                     droplets=path, progress=False, log=quiet)
    assert frame["time"].iloc[-1] == pytest.approx(0.04)
    assert (np.abs(frame["mass_balance_error"]) < 1e-12).all()


def test_case_file_without_feed_section_runs(tmp_path):
    """The property set's default mass rate is 0: a new case file that forgets [feed] starts with no droplets."""
    text = (Path(__file__).resolve().parents[1] / "data" / "cases" / "demo.toml").read_text()
    head, rest = text.split("[feed]", 1)
    path = tmp_path / "nofeed.toml"
    path.write_text(head + rest.split("\n", 2)[2])
    assert "mass_rate" not in path.read_text()
    frame = run_case(load_case(path, SMALL), tmp_path / "out", end_time=0.01, progress=False, log=quiet)
    assert frame["droplet_count"].iloc[-1] == 0


def test_feed_backlog_is_reported(tmp_path):
    """A feed faster than the inlet layer takes falls behind: the backlog is in the time series and said once."""
    said = []
    frame = run_case(load_case("demo", SMALL + ["feed.mass_rate=2", "fulldem.output_interval=0.004"]),
                     tmp_path, end_time=0.012, progress=False, log=said.append)
    backlog = frame["feed_backlog"].to_numpy()
    assert backlog[0] == 0.0 and backlog[-1] > 0.0
    assert any("falls behind" in s and "feed_backlog" in s for s in said)


# ------------------------------------------------------------------------------------------------ the grid
@pytest.mark.parametrize("override, expected", [
    ("fulldem.cell_size=0.007", "must divide every box edge"),
    ("fulldem.cell_size=0.1", "at least 4 cells"),
    ("fulldem.cell_size=0.2", "at least 4 cells"),
    ("fulldem.sigma_cells=0.3", "sigma_cells > 1/sqrt(6)"),
    ("fulldem.cell_size=0.00025", "needs about"),  # a 400^3 grid
    ("fulldem.sigma_cells=100", "more than the box's smallest edge"),  # a 2.5 m kernel in a 0.1 m box
    ("fulldem.dem_step=0.004", "steps per contact"),  # the DEM step equal to the fluid step
    ("fulldem.fluid_step=0.03", "explicit viscous limit"),  # above h^2 / (6 nu) = 0.0292 s of 5 mm cells
])
def test_grid_refusals_name_the_key(override, expected, capsys, tmp_path):
    with pytest.raises(CaseError, match="fulldem"):
        fr.check_case(load_case("demo", [override]))
    from settler.cli import main

    assert main(["full", "demo", override, "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and expected in err and override.split("=")[0] in err, err
    assert not (tmp_path / "o").exists()  # refused before anything was written


def test_the_kernel_width_and_dem_step_limits_are_where_the_refusals_say():
    """The largest sigma_cells and DEM step the refusals allow are accepted, a little more is not; the shortest
    contact they quote is the undamped half-period pi sqrt(m_eff/k) of two of the smallest fed droplets."""
    case = load_case("demo")
    g, fd = case.geometry, case.fulldem
    widest = min(g.width, g.depth, g.height) / (2 * 2.5 * fd.cell_size)  # the stencil spans 2 x 2.5 sigma
    fr.check_case(load_case("demo", [f"fulldem.sigma_cells={widest * (1 - 1e-9)!r}"]))
    with pytest.raises(CaseError, match="sigma_cells"):
        fr.check_case(load_case("demo", [f"fulldem.sigma_cells={widest * (1 + 1e-6)!r}"]))
    from fulldem.stepper import contact_scales

    _, k_min, m_min = contact_scales(case)
    duration = math.pi * math.sqrt(0.5 * m_min / k_min)  # m_eff of two equal droplets: m/2
    most = duration / fr.MIN_CONTACT_STEPS
    fr.check_case(load_case("demo", [f"fulldem.dem_step={most * (1 - 1e-9)!r}"]))
    with pytest.raises(CaseError, match=f"{duration:.3g} s"):
        fr.check_case(load_case("demo", [f"fulldem.dem_step={most * (1 + 1e-6)!r}"]))


def test_an_ignored_sigint_stays_ignored(tmp_path, monkeypatch):
    """A background job started by a shell ignores SIGINT; the run leaves it so (and finishes)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _interrupt_at(monkeypatch, 2, signal.SIGINT)
    frame = run_case(load_case("demo", SMALL), tmp_path, end_time=0.01, progress=False, log=quiet)
    assert frame["time"].iloc[-1] == pytest.approx(0.01)
    assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN


def test_a_checkpoint_from_before_a_key_existed_resumes_only_under_the_keys_old_meaning():
    """A checkpoint's case identity without coalescence.trigger (written before the key existed) matches a case
    with the value that computes what the engine computed then ('first_contact', fr.KEYS_ADDED), and no other."""
    old = fr.case_identity(load_case("demo"))
    del old["coalescence"]["trigger"]
    assert fr.case_differences(old, load_case("demo", ["coalescence.trigger=first_contact"])) == []
    # the default is now the seed paper's rule, which such a checkpoint did not compute
    assert fr.case_differences(old, load_case("demo")) == [
        "coalescence.trigger: checkpoint 'first_contact', now 'every_contact'"]
