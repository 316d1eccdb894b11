"""One level of the hierarchical calibration: a weighted least-squares fit of popbal's [popbal] keys to the
steady-window means of reference runs, its model-discrepancy term and its identifiability gate (SI units).

Residuals. One per run and column (:data:`analysis.calibration.targets.TARGET_COLUMNS`):
r = (reduced window mean - full window mean) / sigma, sigma^2 = se^2 + (delta x abs(full mean))^2, with se the run's
own standard error (:mod:`analysis.calibration.targets`) and delta the **model discrepancy**: a relative error
the model makes whatever its parameters (Kennedy & O'Hagan's term in its simplest form, one relative scale for all
columns). Without it a model that cannot reach the runs' 0.1-1 % scatter gets standard errors that pretend it can.
delta starts where chi^2 = m - p at the start values (0 if below); after each fit it is set so that chi^2 = m - p at
the optimum and the fit is repeated (:data:`DISCREPANCY_ROUNDS` times at most), so the parameters' standard errors
include the model's own misfit.

Gate (before any hold-out is scored; :func:`gate`): every parameter's relative standard error below
:data:`GATE_RELATIVE_ERROR` (0.5), every correlation below :data:`GATE_CORRELATION` (0.9) in magnitude, and every
profile-likelihood interval closed: the profile of chi^2 over a parameter (the others refitted at each point) rises
by :data:`PROFILE_RISE` (3.84, the 95 % point of chi^2 with one degree of freedom) on both sides inside the
parameter's bounds (Raue et al., Bioinformatics 25 (2009) 1923: an open side is a parameter the data do not
determine).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq, least_squares

from .uncertainty import PARAMETERS, parameter_uncertainty

from .targets import TARGET_COLUMNS, Target, window_means

GATE_RELATIVE_ERROR = 0.5
GATE_CORRELATION = 0.9
PROFILE_RISE = 3.84
#: Profile points on each side of the estimate, in steps of this many standard errors (then to the bound).
PROFILE_STEPS = (1.0, 2.0, 4.0)
DISCREPANCY_ROUNDS = 3


def reduced_means(target: Target, case_file, values: dict, fixed: dict | None = None) -> dict[str, float]:
    """The reduced model's :data:`TARGET_COLUMNS` over the target's window: popbal on the reference's resolved case
    ``case_file`` with [popbal] ``values`` and ``fixed`` overrides, run to the window's end."""
    return window_means(reduced_series(target, case_file, values, fixed), target.window)


def reduced_series(target: Target, case_file, values: dict, fixed: dict | None = None):
    """popbal's time series (a pandas DataFrame, rows every 0.5 s) as :func:`reduced_means` runs it."""
    import popbal
    from settler.cases import NO_CALIBRATION, load_case

    # the file's own calibration layer gives way (simple's and cubic's resolved case.toml carry the paper layer's
    # keys, plume_reynolds_scale among them): every run is scored under the closures fitted and nothing else,
    # as a user applying the written layer with case.calibration=NAME gets them
    overrides = {"case.calibration": NO_CALIBRATION}
    overrides.update({f"popbal.{k}": float(v) for k, v in values.items()})
    overrides.update(fixed or {})
    overrides["popbal.end_time"] = target.window[1]
    overrides["popbal.output_interval"] = 0.5
    case = load_case(case_file, overrides)
    return popbal.run(popbal.setup(case), progress=False).timeseries


@dataclass
class LevelFit:
    """A fitted level: estimates, standard errors and correlation of ``parameters``; the discrepancy delta [-];
    chi2 and the residual count; relative errors {run: {column: reduced / full - 1}}; the gate's verdict."""

    level: str
    runs: list[str]
    parameters: list[str]
    estimates: dict[str, float]
    standard_errors: dict[str, float]
    correlation: np.ndarray
    discrepancy: float
    chi2: float
    residual_count: int
    evaluations: int
    status: str
    errors: dict[str, dict[str, float]]
    profiles: dict[str, dict] = field(default_factory=dict)
    gate: dict = field(default_factory=dict)


def _model_or_none(model, target, case_file, values, fixed):
    """One target's model means (here or in a worker process); None where popbal refuses the combination
    (CaseError)."""
    from settler.cases import CaseError

    try:
        return model(target, case_file, values, fixed)
    except CaseError:
        return None


def _one_thread():
    """A worker's initializer: one Numba thread each, so that the workers share the cores instead of crowding them."""
    import os

    os.environ["NUMBA_NUM_THREADS"] = "1"
    os.environ["OMP_NUM_THREADS"] = "1"


def worker_pool(workers: int):
    """A process pool of ``workers`` (spawned, one Numba thread each) for :func:`fit_level`, or None for 1.
    ValueError below 1."""
    if workers < 1:
        raise ValueError(f"workers {workers!r}: allowed an integer >= 1")
    if workers == 1:
        return None
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    return ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"), initializer=_one_thread)


class _Objective:
    """Weighted residuals of a level for parameter vectors; counts evaluations; a refused combination (a channel
    wider than the box) counts as far from every run."""

    def __init__(self, targets, case_files, parameters, fixed, columns, progress, model=None, pool=None):
        self.targets, self.case_files, self.parameters = targets, case_files, list(parameters)
        self.model = model or reduced_means
        self.fixed, self.columns, self.progress = dict(fixed or {}), list(columns), progress
        self.pool = pool  # a process pool: the targets' model runs side by side (the same numbers, sooner)
        self.discrepancy = 0.0
        self.evaluations = 0
        self.last_means: dict[str, dict] = {}

    def sigma(self, target, column):
        return math.hypot(target.standard_errors[column], self.discrepancy * abs(target.means[column]))

    def means(self, x):
        values = dict(zip(self.parameters, x))
        self.evaluations += 1
        if self.progress:
            print(f"\rcalibrate: model run {self.evaluations}", end="", file=sys.stderr, flush=True)
        args = [(self.model, t, self.case_files.get(t.name), values, self.fixed) for t in self.targets]
        if self.pool is not None:
            jobs = [self.pool.submit(_model_or_none, *a) for a in args]
            return {t.name: job.result() for t, job in zip(self.targets, jobs)}
        return {t.name: _model_or_none(*a) for t, a in zip(self.targets, args)}

    def sigmas(self) -> np.ndarray:
        return np.array([self.sigma(t, c) for t in self.targets for c in self.columns])

    def residuals_of(self, means) -> np.ndarray:
        r = []
        for target in self.targets:
            got = means[target.name]
            for column in self.columns:
                value = math.nan if got is None else got[column]
                residual = (value - target.means[column]) / self.sigma(target, column)
                r.append(residual if math.isfinite(residual) else 1e3)
        return np.array(r)

    def __call__(self, x):
        means = self.means(x)
        self.last_means = means
        return self.residuals_of(means)


def _bounds(parameters):
    low = np.array([PARAMETERS[p][0] for p in parameters], dtype=float)
    high = np.array([PARAMETERS[p][1] for p in parameters], dtype=float)
    return low, high


def _least_squares(objective, x0, low, high, budget):
    x0 = np.clip(np.asarray(x0, dtype=float), low + 1e-6 * (high - low), high - 1e-6 * (high - low))
    # relative steps of 1 %: popbal's outputs move in small jumps with a parameter (sections, cells)
    return least_squares(objective, x0, bounds=(low, high), diff_step=1e-2, x_scale=np.maximum(np.abs(x0), 1e-3),
                         max_nfev=max(2, budget), method="trf")


def fit_level(level: str, targets: list[Target], case_files: dict, parameters, start: dict, fixed: dict | None = None,
              columns=tuple(TARGET_COLUMNS), max_evaluations: int = 60, profile: bool = True,
              progress: bool = True, model=None, pool=None) -> LevelFit:
    """Fit ``parameters`` of one level to ``targets`` (module docstring), with the discrepancy and the gate.

    case_files: {run: its resolved case.toml}; start: {parameter: start value}; fixed: {section.key: value} applied
    to every run; max_evaluations: least-squares iterations per round (each costs p + 1 model runs of every target);
    model: (target, case_file, values, fixed) -> {column: window mean}, default :func:`reduced_means` (popbal), a
    module-level function where ``pool`` (:func:`worker_pool`) runs the targets side by side.
    """
    parameters = list(parameters)
    low, high = _bounds(parameters)
    objective = _Objective(targets, case_files, parameters, fixed, columns, progress, model, pool)
    x = np.array([float(start[p]) for p in parameters])
    m, p = len(targets) * len(columns), len(parameters)
    status = ""
    # the first round's weights from the start's misfit, not delta = 0: with delta = 0 the columns whose runs scatter
    # least (the mean diameter, 0.4 %) outweigh the rest a hundredfold and the first round chases them away from the
    # fixed point (delta, x) that the rounds converge to (the zones_core development fit, 2026-12-07)
    objective(x)
    objective.discrepancy = _discrepancy_for(objective, m - p)
    for _ in range(DISCREPANCY_ROUNDS):
        result = _least_squares(objective, x, low, high, max_evaluations)
        x, status = result.x, result.message
        used = objective.sigmas()
        objective(x)  # the model means at the estimate
        previous = objective.discrepancy
        delta = _discrepancy_for(objective, m - p)
        if abs(delta - previous) <= 0.02 * max(delta, 1e-9) or delta == 0.0:
            objective.discrepancy = delta
            break
        objective.discrepancy = delta
    final = objective.residuals_of(objective.last_means)
    chi2 = float(final @ final)
    jacobian = result.jac * (used / objective.sigmas())[:, None]  # the Jacobian under the final sigma
    se_values, correlation, _, _ = parameter_uncertainty(jacobian, final, x, parameters)
    # parameter_uncertainty scales by s^2 = chi^2 / (m - p); the sigmas are the runs' own errors (plus the
    # discrepancy, which brings s^2 to 1 when the model misfits), so a fit better than its sigmas (s^2 < 1) keeps
    # the unscaled errors, the scale of the profile likelihood's threshold
    s2 = chi2 / max(m - p, 1)
    if 0.0 < s2 < 1.0:
        se_values = se_values / math.sqrt(s2)
    relative = {t.name: {c: objective.last_means[t.name][c] / t.means[c] - 1.0 if objective.last_means[t.name] else
                         math.nan for c in columns} for t in targets}
    fit = LevelFit(level=level, runs=[t.name for t in targets], parameters=parameters,
                   estimates=dict(zip(parameters, map(float, x))),
                   standard_errors=dict(zip(parameters, map(float, se_values))),
                   correlation=correlation, discrepancy=objective.discrepancy, chi2=chi2, residual_count=m,
                   evaluations=objective.evaluations, status=str(status), errors=relative)
    if profile:
        fit.profiles = {name: profile_parameter(objective, x, i, chi2, se_values[i], low, high, max_evaluations)
                        for i, name in enumerate(parameters)}
    fit.gate = gate(fit)
    if progress:
        print(file=sys.stderr)
    return fit


def _discrepancy_for(objective, dof) -> float:
    """delta so that sum r^2 = dof at the residuals' model means (solved on a bracket; 0 if already below)."""
    means = objective.last_means

    def excess(delta):
        objective.discrepancy = delta
        r = objective.residuals_of(means)
        return float(r @ r) - max(dof, 1)

    if excess(0.0) <= 0:
        return 0.0
    high = 1e-3
    while excess(high) > 0 and high < 1e3:
        high *= 2.0
    return float(brentq(excess, 0.0, high, xtol=1e-6)) if high < 1e3 else high


def profile_parameter(objective, x, index, chi2_min, se, low, high, budget) -> dict:
    """The profile of chi^2 over parameter ``index``: chi^2 with it pinned at points on each side (steps of
    :data:`PROFILE_STEPS` standard errors, clipped to its bounds) and the others refitted; {"points": [(value,
    chi^2)], "lower", "upper": where chi^2 - min crosses :data:`PROFILE_RISE` (None: open on that side)}."""
    name = objective.parameters[index]
    others = [i for i in range(len(x)) if i != index]
    step = se if math.isfinite(se) and se > 0 else 0.1 * max(abs(x[index]), 1e-3)
    points = [(float(x[index]), chi2_min)]
    crossings = {}
    for side, bound in ((-1, low[index]), (1, high[index])):
        previous = (float(x[index]), 0.0)
        crossings[side] = None
        for k in PROFILE_STEPS:
            value = float(np.clip(x[index] + side * k * step, low[index], high[index]))
            chi2 = _pinned_chi2(objective, x, index, others, value, low, high, budget)
            points.append((value, chi2))
            rise = chi2 - chi2_min
            if rise >= PROFILE_RISE:
                # linear interpolation between the last point below and this one
                v0, r0 = previous
                crossings[side] = v0 + (value - v0) * (PROFILE_RISE - r0) / (rise - r0) if rise != r0 else value
                break
            previous = (value, rise)
            if value in (low[index], high[index]):
                break
    return {"parameter": name, "points": sorted(points), "lower": crossings[-1], "upper": crossings[1]}


def _pinned_chi2(objective, x, index, others, value, low, high, budget) -> float:
    """chi^2 with parameter ``index`` at ``value`` and the ``others`` refitted (a third of the fit's budget)."""
    sub = _Sub(objective, index, value)
    if not others:
        r = sub(np.array([]))
        return float(r @ r)
    result = _least_squares(sub, x[others], low[others], high[others], max(2, budget // 3))
    return float(result.fun @ result.fun)


class _Sub:
    """The objective with parameter ``index`` pinned at ``value``: a function of the others."""

    def __init__(self, objective, index, value):
        self.objective, self.index, self.value = objective, index, value

    def __call__(self, rest):
        x = np.insert(np.asarray(rest, dtype=float), self.index, self.value)
        return self.objective(x)


def gate(fit: LevelFit) -> dict:
    """The identifiability gate (module docstring): {"passed": bool, "reasons": [text]}."""
    reasons = []
    for i, name in enumerate(fit.parameters):
        value, se = fit.estimates[name], fit.standard_errors[name]
        if not (math.isfinite(se) and se < GATE_RELATIVE_ERROR * abs(value)):
            reasons.append(f"{name}: relative standard error {se / abs(value) if value else math.inf:.2g} "
                           f"(limit {GATE_RELATIVE_ERROR:g})")
        for j in range(i + 1, len(fit.parameters)):
            rho = fit.correlation[i, j]
            if not abs(rho) < GATE_CORRELATION:
                reasons.append(f"{name} and {fit.parameters[j]}: correlation {rho:+.3f} (limit {GATE_CORRELATION:g})")
        prof = fit.profiles.get(name)
        if prof is not None:
            open_sides = [side for side in ("lower", "upper") if prof[side] is None]
            if open_sides:
                reasons.append(f"{name}: profile likelihood open on the {' and '.join(open_sides)} side")
    return {"passed": not reasons, "reasons": reasons}
