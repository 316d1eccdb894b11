"""A run's progress line.

:class:`Progress` reports a run's progress: a tqdm bar in a terminal or a notebook, plain lines elsewhere.
"""

from __future__ import annotations

import sys
import time as _time


def _in_notebook() -> bool:
    """True inside a Jupyter/IPython kernel (as tqdm.auto decides between its notebook and terminal bars)."""
    if "ipykernel" not in sys.modules or "IPython" not in sys.modules:
        return False
    try:
        from IPython import get_ipython
    except ImportError:
        return False
    shell = get_ipython()
    return shell is not None and getattr(shell, "kernel", None) is not None


class Progress:
    """Progress of a run over simulated time: a tqdm bar in a terminal or notebook, plain lines elsewhere.

    Where ``stream`` is a terminal, or in a Jupyter/IPython kernel (with the default stream), the progress is a
    tqdm bar over simulated time (tqdm.auto's widget in a notebook): the time as description, the droplet count
    and ``extra`` as postfix, the width fitted to the terminal (or ``ncols``). Elsewhere (log files, pipes) it is
    one plain line per ``interval`` wall seconds, like LIGGGHTS' thermo output::

        t =    1.250 / 10 s ( 12.5 %)  droplets     3125  wall    60.2 s  ETA   301.4 s  Re_cell ...

    Both leave out the first step's pace: it includes the compilation of the Numba kernels (up to a minute on a
    first run). The plain lines' ETA extrapolates the pace since the first report; the bar starts its rate
    estimate (tqdm's exponential moving average) at the first update.

    Every :meth:`update` records the latest state, even one not shown; :meth:`close` shows it (the bar at 100 %
    once ``t`` reached ``t_end``; a last plain line unless that state was already printed) and closes the bar.
    ``close(t)`` records a final time first. ``bar`` forces the choice (True: tqdm bar, False: plain lines).
    """

    def __init__(self, t_start, t_end, enabled=True, interval=1.0, stream=None, *, ncols=None, bar=None):
        self.t_start, self.t_end = float(t_start), float(t_end)
        self.enabled = enabled
        self.interval = interval
        self.stream = stream if stream is not None else sys.stderr
        self.wall_start = _time.perf_counter()
        self.last = -1e30
        self.first = None  # (simulated time, wall clock) of the first report
        self.tty = bool(getattr(self.stream, "isatty", None) and self.stream.isatty())
        notebook = (stream is None or stream is sys.stderr or stream is sys.stdout) and _in_notebook()
        self.state = None  # (t, droplets, extra) of the latest update
        self.shown = True  # whether that state has been shown
        self.closed = False
        self._bar = None
        if enabled and (bar if bar is not None else (self.tty or notebook)):
            self._bar = self._make_bar(notebook, ncols)

    def _make_bar(self, notebook, ncols):
        try:
            if notebook:
                from tqdm.auto import tqdm
            else:
                from tqdm import tqdm
        except ImportError:
            return None  # plain lines
        options = {} if notebook else {"file": self.stream}
        return tqdm(total=self.total, unit="s", ncols=ncols, dynamic_ncols=ncols is None and not notebook,
                    mininterval=min(self.interval, 0.2), miniters=0, leave=True,
                    desc=self._description(self.t_start),
                    bar_format="{desc} {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}{postfix}]", **options)

    @property
    def total(self) -> float:
        """Simulated time of the whole run [s], as the bar's total (1 for a run that has nothing left to do)."""
        return self.t_end - self.t_start if self.t_end > self.t_start else 1.0

    @property
    def is_bar(self) -> bool:
        """Whether the progress is shown as a tqdm bar (else as plain lines)."""
        return self._bar is not None

    def _description(self, t):
        return f"t = {t:.3f}/{self.t_end:g} s"

    def _done(self, t):
        """The bar's position for simulated time t: exactly its total once t is within round-off of t_end."""
        if t >= self.t_end - 1e-9 * max(1.0, abs(self.t_end)):
            return self.total
        return min(max(t - self.t_start, 0.0), self.total)

    def update(self, t, droplets, extra="", force=False):
        """Record simulated time ``t`` [s] and the droplet count; show them if ``interval`` has passed or ``force``."""
        if not self.enabled or self.closed:
            return
        self.state, self.shown = (t, droplets, extra), False
        now = _time.perf_counter()
        if not force and now - self.last < (self._bar.mininterval if self._bar is not None else self.interval):
            return
        self.last = now
        if self._bar is not None:
            self._update_bar(t, droplets, extra, force)
        else:
            self._line(t, droplets, extra, now)
        self.shown = True

    def _update_bar(self, t, droplets, extra, force):
        bar = self._bar
        bar.set_description_str(self._description(t), refresh=False)
        bar.set_postfix_str(f"droplets {droplets}" + (f"  {extra}" if extra else ""), refresh=False)
        done = self._done(t)
        if self.first is None:
            # Jump to the first position without a rate sample: the first step includes the compilation.
            self.first = (t, _time.perf_counter())
            bar.n = bar.initial = bar.last_print_n = done
            bar.last_print_t = bar._time()
            bar.refresh()
        elif force:
            bar.n = done
            bar.refresh()
        else:
            bar.update(done - bar.n)

    def _line(self, t, droplets, extra, now):
        wall = now - self.wall_start
        done = (t - self.t_start) / max(self.t_end - self.t_start, 1e-300)
        if self.first is None:
            self.first = (t, now)
        first_t, first_wall = self.first
        eta = (now - first_wall) * (self.t_end - t) / (t - first_t) if t > first_t else float("nan")
        line = (f"t = {t:8.3f} / {self.t_end:g} s ({100 * done:5.1f} %)  droplets {droplets:8d}  "
                f"wall {wall:7.1f} s  ETA {eta:7.1f} s  {extra}")
        self.stream.write(line + "\n")
        self.stream.flush()

    def close(self, t=None):
        """Show the latest state (``t`` [s], if given, is the final time) and close the bar; idempotent."""
        if not self.enabled or self.closed:
            return
        if t is not None:
            droplets, extra = self.state[1:] if self.state else (0, "")
            self.state, self.shown = (t, droplets, extra), False
        try:
            if self.state is not None and not self.shown:
                self.update(*self.state, force=True)
        finally:
            self.closed = True
            if self._bar is not None:
                self._bar.close()
