"""Size limits of a reduced-model run: how many outputs, and how much memory its arrays would take.

A case or a command line can ask for more than any machine holds (``popbal.height_cells=10000000``,
``popbal.sections_per_doubling=10000``, ``--output-interval 1e-9``). :func:`check` estimates, before anything is
allocated, the bytes the run's arrays will take and refuses with a :class:`settler.cases.CaseError` that names the
keys, the estimate and the limit -- instead of a MemoryError, or memory filling up array by array.

What scales (Z = 2 zones, J cells, K sections, Q = 3 quantities, M velocity-table ages, T outputs):

* state: the content (Z, J, Q, K), the property arrays (3 x (Z, J, K)) and the per-step temporaries;
* section pairs: the grid's merger targets and loss weights, the collision-kernel work array beta, the
  'step'-rule speed-limit table -- all (K, K), plus the temporaries of :func:`popbal.grid.make_grid`;
* the velocity table (K, M);
* the distribution snapshots: per output three (Z, J, K) arrays and six (K,) arrays, held in a list during the
  run and stacked into (T, ...) arrays at the end (so twice), plus a time-series row per output.

Limit (:func:`memory_limit`): a quarter of the machine's physical memory, at most 16 GB. A quarter, because the
estimate counts the arrays only (not Python, NumPy, numba or the writing of distribution.npz) and the machine runs
other things; at most 16 GB, because the reduced model is meant to answer in seconds to minutes -- the presets
take a few MB -- and a run that needs more is almost always a typo; 4 GB where the memory size cannot be read. The
environment variable ``POPBAL_MEMORY_LIMIT_GB`` sets another limit (a number of GB > 0) for a deliberate large run.

Outputs are also capped at :data:`MAX_OUTPUTS`: every output ends a time step and adds a time-series row, so a
tiny output interval means at least that many steps and rows even when the arrays are small.
"""

from __future__ import annotations

import math
import os

from settler.cases import CaseError
from settler.output import PROFILE_BANDS

#: Most outputs (time-series rows and distribution snapshots) a run may write; the presets write 61 to 73.
MAX_OUTPUTS = 100_000

#: Most time steps a run may take, by its lower bound (run length / popbal.time_step): at the simple preset's 0.35 ms
#: per step (1 200 steps in 0.42 s, measured 2026-12-03 on the 2-core machine) 1e7 steps are about an hour; the
#: presets take 1 200-1 500. More is almost always a typo (popbal.time_step = 1e-9 s: 6e10 steps, months).
MAX_STEPS = 10_000_000

#: Upper bound of the memory limit [bytes], and the fraction of physical memory it takes.
MEMORY_CAP = 16e9
MEMORY_FRACTION = 0.25
#: Limit where the physical memory size cannot be read [bytes].
MEMORY_FALLBACK = 4e9
#: Environment variable that sets the limit in GB (10^9 bytes).
MEMORY_LIMIT_VARIABLE = "POPBAL_MEMORY_LIMIT_GB"

ZONE_COUNT = 4  # popbal.model.ZONES: channel, outer, roof layer, bottom layer (model imports this module)
QUANTITY_COUNT = 3
#: Bytes of the (K, K) section-pair arrays: merger targets (int64), loss weights, beta, the 'step'-rule
#: speed-limit table (built from nested lists: a Python float and a list slot per pair before the array), and the
#: peak of make_grid's temporaries (pair sums, searchsorted result, masks, quotients).
PAIR_BYTES = 8 + 8 + 8 + 40
SPEED_TABLE_PAIR_BYTES = 8 + 32
#: Bytes per output beyond its arrays: the time-series row (a dict of floats) and the snapshot's dict and array
#: headers, and the DataFrame row they become.
OUTPUT_OVERHEAD_BYTES = 4096
#: Bytes of a run beyond its arrays and outputs: its model, books and work objects and the time-series frame, about
#: 2 kB over the parts counted here on the simple preset at 40 cells (tracemalloc, 2026-12-06,
#: tests/test_popbal_refusals.py), rounded up [chosen].
RUN_OVERHEAD_BYTES = 65536
#: Bytes per channel-profile row (settler.output.CHANNEL_PROFILE; PROFILE_BANDS rows per output): a dict of five
#: floats, measured 2026-12-02 with tracemalloc at 312 bytes, and its DataFrame row (40 bytes), rounded up.
PROFILE_ROW_BYTES = 400


def physical_memory() -> float | None:
    """Physical memory of this machine [bytes], or None where it cannot be read."""
    try:
        size = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None
    return float(size) if size > 0 else None


def memory_limit() -> tuple[float, str]:
    """The memory limit [bytes] of a run's arrays and a few words on where it comes from."""
    text = os.environ.get(MEMORY_LIMIT_VARIABLE)
    if text is not None and text.strip():
        try:
            gigabytes = float(text)
        except ValueError:
            gigabytes = math.nan
        if not (math.isfinite(gigabytes) and gigabytes > 0.0):
            raise CaseError(f"environment variable {MEMORY_LIMIT_VARIABLE} = {text!r}: allowed a finite number of "
                            "GB > 0 (or unset: a quarter of the machine's memory, at most 16 GB)")
        return gigabytes * 1e9, f"set by {MEMORY_LIMIT_VARIABLE}"
    memory = physical_memory()
    if memory is None:
        return float(MEMORY_FALLBACK), "the machine's memory size is unknown; set another with " \
                                       f"{MEMORY_LIMIT_VARIABLE}"
    limit = min(MEMORY_FRACTION * memory, float(MEMORY_CAP))
    return limit, (f"a quarter of this machine's {size_text(memory)}, at most {size_text(MEMORY_CAP)}; "
                   f"{MEMORY_LIMIT_VARIABLE} sets another")


def size_text(size: float) -> str:
    """A byte count in words: '3.2 GB', '410 kB'."""
    if not math.isfinite(size) or size > 1e300:
        return "over 1e300 bytes"
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if size >= scale:
            return f"{size / scale:.3g} {unit}"
    return f"{size:.0f} bytes"


def count_text(count: float) -> str:
    """A count in words: '6.299e+04', or 'over 1e300'."""
    return f"{count:.4g}" if math.isfinite(count) and count <= 1e300 else "over 1e300"


def real(n) -> float:
    """A count as a float without overflow (a TOML integer may exceed the float range)."""
    return float(n) if abs(n) < 1e300 else math.inf


def section_estimate(volume_min: float, volume_top: float, sections_per_doubling) -> float:
    """Sections the grid will have (as popbal.grid.section_count), for any sections_per_doubling, as a float."""
    from .grid import section_count

    if real(sections_per_doubling) <= 2.0**40:
        return float(section_count(volume_min, volume_top, sections_per_doubling))
    return 1.0 if volume_top <= volume_min else math.inf


def output_count(stop: float, interval: float) -> float:
    """Outputs of a run of ``stop`` seconds at ``interval`` (at most; t = 0 and the end included)."""
    ratio = stop / interval
    return math.ceil(ratio) + 1.0 if math.isfinite(ratio) else math.inf


def estimate(cells, sections: float, outputs: float, ages: int, speed_table: bool) -> dict[str, float]:
    """Bytes of the run's arrays by part: 'state', 'pairs', 'table', 'snapshots' and 'total' (theirs and
    :data:`RUN_OVERHEAD_BYTES`)."""
    j, k, t = real(cells), real(sections), real(outputs)
    field = ZONE_COUNT * j * k * 8.0  # one (Z, J, K) float array
    parts = {
        # content (Q arrays) + diameters, densities, velocities + per-step temporaries (masks, products), the outer
        # zone's entrained amounts per cell (J, Q, K) and its zero loss and source (J,), (Q, K)
        "state": field * (QUANTITY_COUNT + 3 + 2) + 8.0 * ZONE_COUNT * j * 4 + (j + 1.0) * QUANTITY_COUNT * k * 8.0
        + j * 8.0,
        "pairs": k * k * (PAIR_BYTES + (SPEED_TABLE_PAIR_BYTES if speed_table else 0)),
        "table": k * ages * 8.0,
        # three (Z, J, K) and six (K,) arrays per output, twice (the list and the stacked arrays), the rows, and
        # the channel profile's rows
        "snapshots": t * (2.0 * (3.0 * field + 6.0 * 8.0 * k) + OUTPUT_OVERHEAD_BYTES
                          + PROFILE_BANDS * PROFILE_ROW_BYTES),
    }
    parts["total"] = sum(parts.values()) + RUN_OVERHEAD_BYTES
    return parts


#: Steps after which a run checks, every STEP_CHECK_EVERY steps, that the steps it is now taking (shortened below
#: popbal.time_step by the Courant limit of its fastest droplets) leave it within MAX_STEPS: the presets take
#: 1 200-1 500 steps and never reach the check.
STEP_CHECK_AFTER = 10_000
STEP_CHECK_EVERY = 1_000


def check_projected_steps(steps: int, t: float, stop: float, dt: float, fastest: float, max_courant: float,
                          cell_height: float) -> None:
    """Refuse (:class:`settler.cases.CaseError`) a run whose time step dt [s] -- the Courant limit
    ``max_courant`` x ``cell_height`` [m] / ``fastest`` [m/s] where that is below popbal.time_step -- would take it
    past MAX_STEPS steps by the stop time: a feed or a size that makes droplets settle so fast that the run would go
    on for days (feed.mass_rate = 1e6 kg/s in the demo: 3e-6 s steps, 2e7 of them)."""
    if steps < STEP_CHECK_AFTER or steps % STEP_CHECK_EVERY:
        return
    projected = steps + (stop - t) / dt
    if projected > MAX_STEPS:
        raise CaseError(f"the time step has fallen to {dt:.3g} s at t = {t:.4g} s (popbal.max_courant = "
                        f"{max_courant:g} x the {cell_height:.3g} m cells over the fastest droplets' "
                        f"{fastest:.3g} m/s): the run to {stop:g} s would take about {count_text(projected)} steps, "
                        f"allowed at most {MAX_STEPS}; check the feed (feed.mass_rate) and the sizes it grows to "
                        f"(coalescence.size_limit), or run a shorter time")


def _run_length(stop: float, end_name: str, end_value) -> str:
    """'END_NAME = VALUE s' for a refusal, with the run length where it differs (a horizontal run stops at its
    residence time)."""
    over = f" (run length {stop:g} s)" if end_value is not None and stop != end_value else ""
    return f"{end_name} = {end_value!r} s{over}"


def check_outputs(stop: float, interval: float, interval_name: str, end_name: str, end_value) -> float:
    """The number of outputs of a run; CaseError if more than MAX_OUTPUTS."""
    count = output_count(stop, interval)
    if count > MAX_OUTPUTS:
        raise CaseError(f"{interval_name} = {interval!r} s with {_run_length(stop, end_name, end_value)}: "
                        f"{count_text(count)} outputs, allowed at most {MAX_OUTPUTS} (an interval >= "
                        f"{stop / (MAX_OUTPUTS - 1):.4g} s)")
    return count


def check_steps(stop: float, time_step: float, end_name: str, end_value) -> float:
    """The least number of time steps of a run (stop / popbal.time_step; the Courant limit may add more); CaseError
    if more than MAX_STEPS."""
    steps = stop / time_step
    if steps > MAX_STEPS:
        raise CaseError(f"popbal.time_step = {time_step!r} s with {_run_length(stop, end_name, end_value)}: at least "
                        f"{count_text(steps)} time steps, allowed at most {MAX_STEPS} (a time step >= "
                        f"{stop / MAX_STEPS:.4g} s)")
    return steps


def check(cells, sections_per_doubling, sections: float, outputs: float, ages: int, speed_table: bool,
          interval_name: str, interval) -> dict[str, float]:
    """Refuse (CaseError) when the run's arrays would take more than :func:`memory_limit`; else the estimate."""
    parts = estimate(cells, sections, outputs, ages, speed_table)
    limit, where = memory_limit()
    if parts["total"] > limit:
        raise CaseError(
            f"popbal.height_cells = {cells!r}, popbal.sections_per_doubling = {sections_per_doubling!r} "
            f"({count_text(sections)} sections), {interval_name} = {interval!r} s ({count_text(outputs)} outputs): "
            f"the reduced model's arrays would take {size_text(parts['total'])} by estimate (state "
            f"{size_text(parts['state'])}, "
            f"section pairs {size_text(parts['pairs'])}, velocity table {size_text(parts['table'])}, "
            f"distribution snapshots {size_text(parts['snapshots'])}), more than the limit of {size_text(limit)} "
            f"({where}); allowed: fewer height cells, sections per doubling or outputs")
    return parts
