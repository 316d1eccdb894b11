"""Prediction bands: the calibration's uncertainty carried through popbal (SI units).

A band is the spread of popbal's output over parameter samples drawn from the calibration's estimates and
covariance (a Laplace approximation of the posterior: a multivariate normal per level, the levels independent,
as each was fitted with the levels before it held), each sample's output multiplied by exp(delta z) with z a
standard normal per column and delta the fit's relative model discrepancy (what the model gets wrong whatever its
parameters): a log-normal factor, equal to 1 + delta z to first order but never negative, since a count, a size
or a velocity cannot change sign by a misfit (with delta = 0.55, 1 + delta z is below 0 for 1 sample in 30).
Quantiles :data:`QUANTILES` (5 %, 50 %, 95 %) give the 90 % band.

:func:`covariance_from_layer` reads a layer written by ``settler calibrate --set`` (its [provenance] tables);
:func:`parameter_samples` draws; :func:`band` runs a model over the samples; :func:`coverage` is the check the
issue asks for: the share of held-out window means inside their 90 % band (about 0.9 if the bands are honest).
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
from scipy.linalg import block_diag

from .uncertainty import PARAMETERS

QUANTILES = (0.05, 0.5, 0.95)

#: The hierarchical layer (data/calibration/<name>.toml) whose bands the calibration and trends reports and the
#: furnace band draw: the latest ``settler calibrate --set`` layer whose gate passed.
CURRENT_LAYER = "zones_core"


def covariance_from_layer(path) -> tuple[dict[str, float], np.ndarray, list[str], float]:
    """(estimates {key: value}, covariance (p, p), keys in its order, the largest level discrepancy delta [-]) of
    a hierarchical calibration layer: the collision level's E with its standard error, each fitted level's
    estimates, standard errors and correlations (block-diagonal between levels), and the values measured before the
    fit with their standard errors where the layer records them ([provenance.measured], each its own block; a
    layer written before 2026-12-07 has none)."""
    layer = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    provenance = layer.get("provenance", {})
    collision = provenance.get("collision")
    if collision is None:
        raise ValueError(f"{path}: no [provenance.collision]; a band needs a layer of 'settler calibrate --set'")
    keys = ["collision_efficiency"]
    estimates = {"collision_efficiency": float(collision["efficiency"])}
    blocks = [np.array([[float(collision["standard_error"]) ** 2]])]
    delta = 0.0
    for level in ("transport", "whole"):
        table = provenance.get(level)
        if table is None:
            continue
        names = [k for k in table if k in PARAMETERS and isinstance(table[k], list)]
        se = np.array([float(table[n][1]) for n in names])
        corr = np.array([[float(v) for v in table[f"correlation_{n}"]] for n in names])
        blocks.append(corr * np.outer(se, se))
        for n in names:
            keys.append(n)
            estimates[n] = float(table[n][0])
        delta = max(delta, float(table.get("discrepancy", 0.0)))
    for name, entry in provenance.get("measured", {}).items():
        if not (isinstance(entry, list) and len(entry) == 2) or name in keys:
            raise ValueError(f"{path}: [provenance.measured] {name} = {entry!r}: allowed [value, standard error] of a "
                             "value measured before the fit, not one of the fitted parameters")
        value, se = entry
        if name in PARAMETERS and math.isfinite(float(se)) and float(se) > 0.0:
            keys.append(name)
            estimates[name] = float(value)
            blocks.append(np.array([[float(se) ** 2]]))
    return estimates, block_diag(*blocks), keys, delta


def parameter_samples(estimates: dict, covariance, keys, count: int, seed: int = 0) -> list[dict[str, float]]:
    """``count`` draws of {key: value} from N(estimates, covariance), each value clipped into its key's bounds
    (:data:`analysis.calibrate.PARAMETERS`)."""
    rng = np.random.default_rng(seed)
    mean = np.array([estimates[k] for k in keys])
    draws = rng.multivariate_normal(mean, np.asarray(covariance, dtype=float), size=count, method="eigh")
    low = np.array([PARAMETERS[k][0] for k in keys])
    high = np.array([PARAMETERS[k][1] for k in keys])
    return [dict(zip(keys, np.clip(row, low, high))) for row in draws]


def band(model, samples, delta: float = 0.0, seed: int = 0, quantiles=QUANTILES, pool=None) -> dict[str, np.ndarray]:
    """{column: array (len(quantiles), ...)} of ``model(values) -> {column: value or array}`` over the parameter
    ``samples``, each output times exp(delta z), z ~ N(0, 1) per sample and column. ``pool`` (a process pool, with
    a picklable ``model``) runs the samples side by side: the same band."""
    rng = np.random.default_rng(seed + 1)
    outputs: dict[str, list] = {}
    if pool is not None:
        jobs = [pool.submit(model, values) for values in samples]
        results = (job.result() for job in jobs)
    else:
        results = map(model, samples)
    for result in results:
        for column, value in result.items():
            outputs.setdefault(column, []).append(np.asarray(value, dtype=float) * math.exp(delta * rng.normal()))
    return {c: np.nanquantile(np.stack(v), quantiles, axis=0) for c, v in outputs.items()}


def coverage(bands: dict[str, dict[str, np.ndarray]], observed: dict[str, dict[str, float]]) -> dict:
    """The share of observed values inside their band (first to last quantile): ``bands`` {run: {column: (q,)}},
    ``observed`` {run: {column: value}}. Returns {"inside", "total", "share", "outside": [(run, column)]}."""
    inside, total, outside = 0, 0, []
    for run, columns in observed.items():
        for column, value in columns.items():
            if run not in bands or column not in bands[run] or not math.isfinite(value):
                continue
            q = bands[run][column]
            total += 1
            if q[0] <= value <= q[-1]:
                inside += 1
            else:
                outside.append((run, column))
    return {"inside": inside, "total": total, "share": inside / total if total else math.nan, "outside": outside}


def layer_samples(layer: str | None, count: int, seed: int = 0) -> tuple[list[dict[str, float]], float]:
    """(``count`` parameter draws, the discrepancy delta [-]) of the calibration layer named ``layer``
    (data/calibration/<layer>.toml, written by ``settler calibrate --set``; None: :data:`CURRENT_LAYER`). Raises
    ValueError for a layer without the hierarchy's provenance (a one-level layer such as ``paper`` records no
    covariance between its levels), settler.cases.CaseError for a name that is not a layer."""
    from settler.cases import calibration_path, read_calibration

    layer = layer or CURRENT_LAYER
    read_calibration(layer)  # the clear error for a name that is not a layer
    estimates, covariance, keys, delta = covariance_from_layer(calibration_path(layer))
    return parameter_samples(estimates, covariance, keys, count, seed=seed), delta


def sample_runs(case_file, layer: str | None, count: int, end_time: float, output_interval: float, seed: int = 0,
                progress=None) -> tuple[list, float]:
    """popbal's time series (pandas DataFrames, SI units) on the case ``case_file`` with the calibration layer
    ``layer`` (None: :data:`CURRENT_LAYER`) applied (``case.calibration = layer``: its [popbal] values replace the
    case's) and each of ``count`` parameter draws of :func:`layer_samples` on top, run to ``end_time`` [s] with rows
    every ``output_interval`` [s]; and the layer's discrepancy delta [-]. ``progress``: a callable of (done, total)
    or None."""
    import popbal
    from settler.cases import load_case

    layer = layer or CURRENT_LAYER
    draws, delta = layer_samples(layer, count, seed)
    series = []
    for k, values in enumerate(draws):
        overrides = {"case.calibration": layer, **{f"popbal.{key}": float(v) for key, v in values.items()},
                     "popbal.end_time": float(end_time), "popbal.output_interval": float(output_interval)}
        series.append(popbal.run(popbal.setup(load_case(case_file, overrides)), progress=False).timeseries)
        if progress is not None:
            progress(k + 1, count)
    return series, delta


def discrepancy_factors(count: int, columns, delta: float, seed: int = 0) -> dict[str, np.ndarray]:
    """{column: (count,) factors exp(delta z)}, z ~ N(0, 1) per sample and column: the model discrepancy of
    :func:`band`, one factor for a whole time series of a sample."""
    rng = np.random.default_rng(seed + 1)
    return {c: np.exp(delta * rng.normal(size=count)) for c in columns}
