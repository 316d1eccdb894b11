"""The Python API of the CFD-DEM engine, of the same shape as popbal's::

    import fulldem
    setup = fulldem.setup("demo", fulldem__end_time=2.0)      # overrides as section__key=value, a dict or a list
    result = fulldem.run(setup, out="runs/demo", progress=False)
    result.timeseries                                          # DataFrame: the columns of settler.output.TIME_SERIES
    result.metadata, result.summary                            # dicts from metadata.json and summary.json
    result.droplets()                                          # the droplets at the end (arrays, SI units)
    fulldem.load("runs/demo")                                  # the same Result from a finished run's folder

``settler full`` is a thin wrapper of :func:`run`. A run writes its outputs into ``out`` as described in
:mod:`fulldem.driver`; :func:`run` refuses bad input with :class:`settler.cases.CaseError` or
:class:`fulldem.driver.RunError` (the command line prints those in one line) and, when stopped by SIGINT or SIGTERM,
saves a checkpoint and raises :class:`fulldem.driver.RunInterrupted` (continue with ``resume=True``).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from settler.cases import Case, case_with_overrides, load_case
from settler.output import read_time_series


@dataclass(frozen=True)
class Setup:
    """What a run needs besides its output folder: the resolved ``case``, an optional initial ``droplets`` list
    (CSV path, see :mod:`fulldem.io.droplet_list`) and ``feed`` (None: on when feed.mass_rate > 0)."""

    case: Case
    droplets: str | os.PathLike | None = None
    feed: bool | None = None

    @property
    def name(self) -> str:
        return self.case.case.name


def setup(case: str | os.PathLike | Case, overrides: dict | list | None = None, *, droplets=None, feed=None,
          **keyword_overrides) -> Setup:
    """A run of a case: a preset name, a TOML path or a :class:`settler.cases.Case`.

    Overrides as ``{"fulldem.end_time": 2}``, ``["fulldem.end_time=2"]`` or keywords ``fulldem__end_time=2``.
    droplets: initial droplets (CSV path); feed: True/False to force the droplet feed on/off. The case is validated
    here, including what the engine needs of it (:func:`fulldem.driver.check_case`): a bad value raises
    :class:`settler.cases.CaseError` naming the key, the value and what is allowed.
    """
    from .driver import check_case

    case = case_with_overrides(case, overrides, **keyword_overrides)
    check_case(case)
    return Setup(case, droplets, feed)


@dataclass
class Result:
    """A run's outputs, read from its folder ``out``: ``timeseries`` (DataFrame with the columns of
    settler.output.TIME_SERIES), ``metadata`` (metadata.json) and ``summary`` (summary.json, empty if the run did not
    finish)."""

    out: Path
    timeseries: pd.DataFrame
    metadata: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)

    @property
    def case(self) -> Case:
        """The resolved case the run used (its case.toml)."""
        return load_case(self.out / "case.toml")

    def droplets(self, checkpoint: str = "checkpoint.npz") -> dict[str, np.ndarray]:
        """The droplets of the run's last checkpoint: every field of fulldem.droplets.FIELDS (SI units, see there)."""
        with np.load(self.out / checkpoint) as data:
            return {k[len("droplet_"):]: data[k] for k in data.files if k.startswith("droplet_")}


def load(out: str | os.PathLike) -> Result:
    """The :class:`Result` of the run in folder ``out`` (finished or stopped: what it has written so far)."""
    out = Path(out)
    if not (out / "timeseries.csv").is_file():
        raise FileNotFoundError(f"{out}: no timeseries.csv; not the folder of a settler full run")

    def read_json(name):
        path = out / name
        return json.loads(path.read_text()) if path.is_file() else {}

    return Result(out, read_time_series(out / "timeseries.csv"), read_json("metadata.json"),
                  read_json("summary.json"))


def run(what: Setup | Case | str, out: str | os.PathLike, *, end_time: float | None = None, resume: bool = False,
        overwrite: bool = False, progress: bool = True, log=print, command: str | None = None,
        **overrides) -> Result:
    """Run a :class:`Setup` (or a case / preset name / path, with ``overrides`` as in :func:`setup`) into folder
    ``out`` and return its :class:`Result`.

    end_time [s] overrides fulldem.end_time; resume continues the run in ``out`` from its checkpoint (same case
    only); overwrite replaces another run's files in ``out`` (else refused); progress shows a bar or progress lines;
    log receives the run's messages (default print); command is recorded in metadata.json.
    """
    from .driver import run_case

    if isinstance(what, Setup):
        if overrides:
            raise TypeError(f"run: overrides {sorted(overrides)} with a Setup; give them to fulldem.setup")
    else:
        what = setup(what, **overrides)
    run_case(what.case, out, end_time=end_time, resume=resume, droplets=what.droplets, feed=what.feed,
             progress=progress, log=log, overwrite=overwrite, command=command)
    return load(out)
