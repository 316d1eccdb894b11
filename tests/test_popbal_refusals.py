"""popbal refuses sizes and times it cannot run: one line naming the key or option, the value and what is allowed,
exit status 2 on the command line, CaseError / ValueError from the Python API -- never a MemoryError or a traceback,
and before anything large is allocated."""

import math
import tracemalloc

import pytest

import popbal
from popbal import limits
from settler.cases import CaseError
from settler.cli import main


def refused(capsys, tmp_path, *argv) -> str:
    """Run ``settler reduced simple ARGV --out DIR``: it must exit 2 with one error line and write no outputs."""
    out = tmp_path / "out"
    assert main(["reduced", "simple", *argv, "--out", str(out), "--quiet"]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("settler reduced: error: "), captured.err
    assert "Traceback" not in captured.err + captured.out and "MemoryError" not in captured.err
    assert not (out / "distribution.npz").exists() and not (out / "timeseries.csv").exists()
    return lines[0]


def refused_by_argparse(capsys, tmp_path, *argv) -> str:
    """argparse refuses an option: SystemExit(2), usage and one error line, no traceback."""
    with pytest.raises(SystemExit) as exit_info:
        main(["reduced", "simple", *argv, "--out", str(tmp_path / "out"), "--quiet"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err.strip().splitlines()[-1]


# ------------------------------------------------------------------------------------------------- memory and size
def test_ten_million_cells_refused_with_the_estimate_and_the_limit(capsys, tmp_path):
    line = refused(capsys, tmp_path, "popbal.height_cells=10000000")
    assert "popbal.height_cells = 10000000" in line
    # 61 snapshots of 3 x (4, 1e7, 20) floats (four zones), twice, dominate (2.34 TB); the state 57 GB
    assert "2.4 TB by estimate" in line
    limit, _ = limits.memory_limit()
    assert f"more than the limit of {limits.size_text(limit)}" in line
    assert "fewer height cells" in line


def test_ten_thousand_sections_per_doubling_refused_for_the_section_pairs(capsys, tmp_path):
    line = refused(capsys, tmp_path, "popbal.sections_per_doubling=10000")
    assert "popbal.sections_per_doubling = 10000 (6.299e+04 sections)" in line
    assert "section pairs 413 GB" in line  # (K, K) merger targets, loss weights, beta, speed-limit table


def test_a_python_integer_beyond_the_float_range_is_refused_not_overflowed(capsys, tmp_path):
    line = refused(capsys, tmp_path, "popbal.sections_per_doubling=" + "9" * 400)
    assert "over 1e300 sections" in line and "over 1e300 bytes by estimate" in line


def test_the_api_refuses_before_allocating():
    tracemalloc.start()
    try:
        with pytest.raises(CaseError, match=r"popbal\.sections_per_doubling = 10000 .*more than the limit"):
            popbal.setup("deep", popbal__sections_per_doubling=10000)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 50e6  # the old code built (K, K) = (2.1e5)^2 arrays before anything could object


def test_the_limit_is_a_quarter_of_memory_capped_and_can_be_set(monkeypatch):
    monkeypatch.delenv(limits.MEMORY_LIMIT_VARIABLE, raising=False)
    limit, where = limits.memory_limit()
    memory = limits.physical_memory()
    assert limit == (min(memory / 4, 16e9) if memory else 4e9)
    monkeypatch.setenv(limits.MEMORY_LIMIT_VARIABLE, "0.5")
    assert limits.memory_limit() == (0.5e9, f"set by {limits.MEMORY_LIMIT_VARIABLE}")
    monkeypatch.setenv(limits.MEMORY_LIMIT_VARIABLE, "lots")
    with pytest.raises(CaseError, match=r"POPBAL_MEMORY_LIMIT_GB = 'lots': allowed a finite number of GB > 0"):
        limits.memory_limit()


def test_just_over_a_set_limit_is_refused_and_just_under_runs(monkeypatch):
    model = popbal.setup("simple", popbal__height_cells=10, popbal__sections_per_doubling=1)
    need = limits.estimate(model.cells, model.grid.size, 4, 1, True)["total"]
    monkeypatch.setenv(limits.MEMORY_LIMIT_VARIABLE, repr(0.99 * need / 1e9))
    with pytest.raises(CaseError, match=r"popbal\.height_cells = 10, .*output_interval = 0\.1 s \(4 outputs\)"):
        popbal.run(model, end_time=0.3, output_interval=0.1)
    monkeypatch.setenv(limits.MEMORY_LIMIT_VARIABLE, repr(1.01 * need / 1e9))
    assert len(popbal.run(model, end_time=0.3, output_interval=0.1).timeseries) == 4


def test_the_estimate_counts_what_a_run_allocates():
    model = popbal.setup("simple", popbal__height_cells=40, popbal__sections_per_doubling=2)
    tracemalloc.start()
    try:
        result = popbal.run(model, end_time=0.2, output_interval=0.02, progress=False)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    outputs = len(result.timeseries)
    parts = limits.estimate(model.cells, model.grid.size, outputs, 1, True)
    snapshots = sum(result.arrays[k].nbytes for k in result.arrays if result.arrays[k].ndim > 1)
    assert parts["snapshots"] >= 2 * snapshots  # the list of snapshots and their stacked copy
    assert parts["total"] >= peak


# --------------------------------------------------------------------------------------------------------- outputs
def test_a_nanosecond_output_interval_is_refused_with_the_count(capsys, tmp_path):
    line = refused(capsys, tmp_path, "--output-interval", "1e-9")
    assert "--output-interval = 1e-09 s with popbal.end_time = 60.0 s: 6e+10 outputs" in line
    assert f"allowed at most {limits.MAX_OUTPUTS} (an interval >= 0.0006 s)" in line


def test_a_tiny_case_output_interval_is_refused(capsys, tmp_path):
    line = refused(capsys, tmp_path, "popbal.output_interval=1e-5")
    assert "popbal.output_interval = 1e-05 s with popbal.end_time = 60.0 s: 6e+06 outputs" in line


def test_the_end_time_option_counts_too(capsys, tmp_path):
    line = refused(capsys, tmp_path, "--end-time", "1e9")
    assert "popbal.output_interval = 1.0 s with --end-time = 1000000000.0 s: 1e+09 outputs" in line


def test_horizontal_flow_counts_outputs_up_to_the_residence_time():
    model = popbal.setup("furnace", popbal__height_cells=4, popbal__sections_per_doubling=1)
    assert model.horizontal and model.stop_time == pytest.approx(21600.0, rel=0.01)
    with pytest.raises(CaseError, match=r"^output_interval = 0\.01 s with end_time = 1e\+30 s \(run "
                                        r"length 21600 s\): 2\.16e\+06 outputs"):
        popbal.run(model, end_time=1e30, output_interval=0.01)


def test_the_api_refuses_too_many_outputs_without_building_them():
    model = popbal.setup("simple", popbal__height_cells=10, popbal__sections_per_doubling=1)
    with pytest.raises(CaseError, match=r"^output_interval = 1e-09 s with popbal\.end_time = 60\.0 s: 6e\+10 outputs"):
        popbal.run(model, output_interval=1e-9)
    with pytest.raises(CaseError, match=r"^popbal\.output_interval = 1e-09 s"):
        popbal.setup("simple", popbal__output_interval=1e-9)


# ------------------------------------------------------------------------------------------- --end-time and friends
@pytest.mark.parametrize("option", ["--end-time", "--output-interval"])
@pytest.mark.parametrize("value", ["-1", "0", "nan", "inf", "-inf", "soon"])
def test_time_options_must_be_finite_and_positive(capsys, tmp_path, option, value):
    # argparse reads a separate "-inf" as an option, so that one is written --option=-inf
    line = refused_by_argparse(capsys, tmp_path, *([f"{option}={value}"] if value == "-inf" else [option, value]))
    assert line.startswith(f"settler reduced: error: argument {option}: ")
    assert value in line and "allowed: a finite number of seconds > 0" in line


@pytest.mark.parametrize("argument", ["end_time", "output_interval"])
@pytest.mark.parametrize("value", [-1.0, 0.0, math.nan, math.inf, -math.inf, "10", True])
def test_run_refuses_bad_times_naming_the_argument(argument, value):
    model = popbal.setup("simple", popbal__height_cells=10, popbal__sections_per_doubling=1)
    with pytest.raises(ValueError, match=rf"^{argument} = .*allowed: a finite number of seconds > 0"):
        popbal.run(model, **{argument: value})


def test_horizontal_run_refuses_an_infinite_end_time():
    # min(inf, residence time) used to hide the infinity and run to the residence time
    model = popbal.setup("furnace", popbal__height_cells=4, popbal__sections_per_doubling=1)
    with pytest.raises(ValueError, match=r"^end_time = inf s"):
        popbal.run(model, end_time=math.inf)


def test_a_run_of_months_of_time_steps_is_refused_before_it_starts(capsys, tmp_path):
    """popbal.time_step = 1e-9 s over the simple preset's 60 s is at least 6e10 steps (months at the preset's 0.35 ms
    per step): refused in one line with the least time step allowed, where it used to run until killed."""
    line = refused(capsys, tmp_path, "popbal.time_step=1e-9")
    assert "popbal.time_step = 1e-09 s" in line and "6e+10 time steps" in line
    assert f"at most {limits.MAX_STEPS}" in line and f"{60.0 / limits.MAX_STEPS:.4g} s" in line
    # the library refuses it too, and a time step just above the bound is accepted by the check
    with pytest.raises(CaseError, match="popbal.time_step"):
        popbal.run(popbal.setup("simple", {"popbal.time_step": 1e-9}))
    model = popbal.setup("simple", {"popbal.time_step": 1.01 * 60.0 / limits.MAX_STEPS})
    popbal.driver.check_run(model)


def test_a_run_whose_steps_shrink_past_the_step_limit_is_stopped_with_the_cause(capsys, tmp_path):
    """feed.mass_rate = 1e6 kg/s in the demo: droplets grow until the Courant limit of the fastest shortens the
    steps to microseconds (2e7 of them to 60 s: it used to run until killed). After STEP_CHECK_AFTER steps the run
    projects its remaining steps and stops in one line naming the step, the speed and the keys to look at."""
    out = tmp_path / "out"
    assert main(["reduced", "demo", "feed.mass_rate=1e6", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    line = err[-1]  # (after the plausibility warnings)
    assert line.startswith("settler reduced: error: ") and "Traceback" not in "\n".join(err)
    assert not (out / "timeseries.csv").exists()
    assert "time step has fallen" in line and "feed.mass_rate" in line and f"at most {limits.MAX_STEPS}" in line


def test_the_projected_step_check_counts_the_remaining_steps():
    """check_projected_steps: steps + (stop - t) / dt against MAX_STEPS, checked only after STEP_CHECK_AFTER steps
    and every STEP_CHECK_EVERY."""
    after, every, most = limits.STEP_CHECK_AFTER, limits.STEP_CHECK_EVERY, limits.MAX_STEPS
    dt = 1.0
    limits.check_projected_steps(after, 0.0, most - after - 1.0, dt, 1.0, 1.0, 1.0)  # just within: accepted
    with pytest.raises(CaseError, match="time step has fallen"):
        limits.check_projected_steps(after, 0.0, most - after + 1.0, dt, 1.0, 1.0, 1.0)
    limits.check_projected_steps(after - every, 0.0, 1e300, dt, 1.0, 1.0, 1.0)  # before the first check
    limits.check_projected_steps(after + 1, 0.0, 1e300, dt, 1.0, 1.0, 1.0)  # between checks
