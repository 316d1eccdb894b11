"""Designs over the axes: the full factorial grid, and Latin-hypercube, Sobol' and Morris samples drawn with SALib
(see :mod:`analysis.sweep`, *Designs*).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from settler.cases import CaseError

from .axes import Axis, _field


DESIGNS = ("grid", "lhs", "sobol", "morris")
#: --samples when not given: LHS points, Sobol base samples N (N (D + 2) points), Morris trajectories (N (D + 1)).
DEFAULT_SAMPLES = {"lhs": 32, "sobol": 16, "morris": 10}
#: Levels of the Morris grid (SALib's default; elementary-effect step 2/3 of the range).
MORRIS_LEVELS = 4


@dataclass
class Design:
    """The points of a design: ``table`` one row per point, one column per swept key (values as given to the
    case); ``problem`` and ``samples`` (the SALib problem and its sample matrix, in log10 for log axes) for
    sampled designs."""

    name: str
    swept: list[Axis]
    fixed: dict
    table: pd.DataFrame
    problem: dict | None = None
    samples: np.ndarray | None = None


def _salib_name(axis: Axis) -> str:
    return f"log10({axis.key})" if axis.log else axis.key


def build_design(axes: list[Axis], design: str = "grid", samples: int | None = None, seed: int = 0) -> Design:
    """The design's points (see the module docstring). CaseError for a design that the axes cannot make."""
    if design not in DESIGNS:
        raise CaseError(f"--design {design!r}: allowed: " + ", ".join(DESIGNS))
    fixed = {a.key: a.values[0] for a in axes if a.fixed}
    swept = [a for a in axes if not a.fixed]
    if design == "grid":
        if samples is not None:
            raise CaseError(f"--samples {samples}: allowed only with --design lhs, sobol or morris (a grid has the "
                            "points of its axes)")
        bare = [a for a in swept if a.values is None]
        if bare:
            raise CaseError(f"sweep axis {bare[0].key} = {bare[0].spec!r}: a grid needs the number of values: a:b:n")
        rows = list(itertools.product(*(a.values for a in swept)))
        table = pd.DataFrame(rows if swept else [()], columns=[a.key for a in swept])
        return Design(design, swept, fixed, table)
    not_range = [a for a in swept if not a.is_range]
    if not swept:
        raise CaseError(f"--design {design}: needs at least one range axis section.key=a:b")
    if not_range:
        raise CaseError(f"sweep axis {not_range[0].key} = {not_range[0].spec!r}: --design {design} samples ranges; "
                        "allowed: a:b (or a:b:n, n unused; a:b:n:log for a log scale)")
    n = DEFAULT_SAMPLES[design] if samples is None else samples
    if isinstance(n, bool) or not isinstance(n, int) or n < (1 if design == "lhs" else 2):
        raise CaseError(f"--samples {n!r}: allowed: an integer >= {1 if design == 'lhs' else 2}")
    if design == "sobol" and n & (n - 1):
        raise CaseError(f"--samples {n}: allowed: a power of 2 for --design sobol (Sobol' sequences are balanced at "
                        "2^k points)")
    problem = {"num_vars": len(swept), "names": [_salib_name(a) for a in swept],
               "bounds": [[math.log10(a.low), math.log10(a.high)] if a.log else [a.low, a.high] for a in swept]}
    x = _sample(design, problem, n, seed)
    table = pd.DataFrame({a.key: _from_sample(a, x[:, i]) for i, a in enumerate(swept)})
    return Design(design, swept, fixed, table, problem, x)


def _sample(design: str, problem: dict, n: int, seed: int) -> np.ndarray:
    """SALib's sample matrix (points x keys) of a sampled design."""
    from ..extras import require

    require("SALib")
    from SALib.sample import latin, morris, sobol

    if design == "lhs":
        return latin.sample(problem, n, seed=seed)
    if design == "sobol":
        return sobol.sample(problem, n, calc_second_order=False, seed=seed)
    return morris.sample(problem, n, num_levels=MORRIS_LEVELS, seed=seed)


def _from_sample(axis: Axis, column: np.ndarray) -> list:
    values = 10.0**column if axis.log else column
    if _field(axis.key).kind is int:
        return [int(round(v)) for v in values]
    return [float(v) for v in values]
