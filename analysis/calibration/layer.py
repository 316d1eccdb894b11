"""The hierarchical calibration as a calibration layer (``data/calibration/<name>.toml``): the [popbal] values every
level determined, each with its source tag and standard error, and a [provenance] table with the command, the
code commit, the registry, every level's fit (runs, chi^2, discrepancy, correlations, profile intervals, gate) and
the hold-outs' errors, or why they were not scored. No machine paths: files are named relative to the repository.
"""

from __future__ import annotations

import datetime
import os
from pathlib import Path

from settler.output import OutputError, atomic_write_text, source_commit

from .hierarchy import CLOSURES, FORM, SWITCH_NOTES, TARGETS, Hierarchy
from .uncertainty import PARAMETERS


def _q(text) -> str:
    return '"' + str(text).replace("\\", "\\\\").replace('"', '\\"') + '"'


def _portable(path) -> str:
    """``path`` relative to the working folder when inside it, else its name alone (never a machine folder)."""
    path = Path(path)
    try:
        return Path(os.path.relpath(path.resolve(), Path.cwd())).as_posix() if path.resolve().is_relative_to(
            Path.cwd()) else path.name
    except ValueError:
        return path.name


def _float(value) -> str:
    return "nan" if value is None else repr(float(value))


def _targets_line(result: Hierarchy) -> str:
    """How many window means meet the issue's targets (10 % fitted, 20 % held out): the gate tests whether the
    parameters are determined, not whether the model is right, so the layer says both."""
    fitted = [abs(e) for fit in result.levels for errors in fit.errors.values() for e in errors.values()]
    held = [abs(e) for errors in (result.holdout_errors or {}).values() for e in errors.values()]
    text = (f"# Targets: {sum(e <= TARGETS['fitted'] for e in fitted)} of {len(fitted)} fitted window means within "
            f"{100 * TARGETS['fitted']:.0f} %")
    if result.holdout_errors is not None:
        text += (f", {sum(e <= TARGETS['holdout'] for e in held)} of {len(held)} held-out within "
                 f"{100 * TARGETS['holdout']:.0f} %")
    return text + "."


def layer_text(result: Hierarchy, registry_path, command: str = "") -> str:
    """The layer's TOML text (module docstring)."""
    commit = source_commit()
    k_r = result.radius_factor
    c = result.collision
    lines = ["# popbal's closures from the hierarchical calibration against the reference set",
             "# (settler calibrate --set; analysis/calibration). Level 1 the kernel run, level 2 the coalescence-off",
             "# runs, level 3 the whole runs; the pre-registered hold-outs are scored only if every level passes",
             "# the identifiability gate.",
             _targets_line(result),
             f"# Gate {'PASSED' if result.gate_passed else 'FAILED'}"
             + ("" if result.gate_passed else ": the values below are not to be used for predictions (no preset "
                                                "applies this layer)") + ".", "", "[popbal]",
             f"collision_efficiency = {c['efficiency']!r}  # - [derived] level collision: the kernel run's merges "
             f"over its gravitational collisions{' cell by cell' if c.get('form') == 'cell' else ''}, standard error "
             f"{c['standard_error']:.3g}"]
    if not any("channel_radius_factor" in fit.parameters for fit in result.levels):  # else fitted, below
        lines.append(f"channel_radius_factor = {k_r['value']!r}  # - [derived] phi_p^(-1/2) of the plume core's "
                     f"volume fraction {k_r['core_fraction']:.4g} in the zone diagnostics of "
                     f"{', '.join(k_r['runs'])}" + (" (the dilution law's Re -> 0 limit)" if "reynolds" in k_r else ""))
    if "reynolds" in k_r:
        lines.append(f"plume_dilution_reynolds = {k_r['reynolds']!r}  # - [derived] Re_d of phi_p = k_R^-2 / (1 + Re "
                     f"/ Re_d) over the same zone diagnostics, standard error "
                     f"{k_r['standard_errors']['plume_dilution_reynolds']:.3g}")
    if result.roof:
        r = result.roof
        lines.append(f"roof_layer_coefficient = {r['coefficient']!r}  # - [derived] the geometric mean of "
                     f"j mu / (drho g I^2) over the roof layers of {', '.join(r['runs'])} (zones.csv)")
        if CLOSURES[result.closures].get("drainage"):
            lines += ["roof_thickness_form = \"drainage\"  # [chosen] the roof's thickness from the drainage law",
                      f"roof_drainage_ratio = {r['drainage_ratio']!r}  # - [derived] the geometric mean of "
                      f"j delta / (I U_s) over the roof layers of {', '.join(r['drainage_per_run'])} (zones.csv; "
                      "cells that resolve the roof)"]
        else:
            lines.append(f"roof_thickness = {r['thickness']!r}  # m [derived] the mean roof thickness of "
                         f"{', '.join(r['runs'])}")
        if "kernel" in r:
            k = r["kernel"]
            lines += [f"roof_collision_efficiency = {k['efficiency']!r}  # - [derived] the geometric mean of the "
                      "top band's merges under the inlet over its well-mixed collisions carried over to the roof "
                      f"layer at popbal's roof thickness, in {', '.join(k['runs'])} (collisions_by_height.csv, "
                      "zones.csv)",
                      f"roof_shear_coefficient = {k['shear_coefficient']!r}  # - [derived] the geometric mean of "
                      f"the shear rate there times popbal's roof thickness over the layer's drainage velocity, in "
                      f"{', '.join(k['runs'])}"]
    if result.floor:
        f = result.floor
        lines.append(f"bottom_layer_factor = {f['value']!r}  # - [derived] the geometric mean of the floor layer's "
                     f"thickness over popbal's channel radius in {', '.join(f['runs'])} (floor_layer.csv), standard "
                     f"error {f['standard_error']:.3g}, spread x{f['spread']:.3g}"
                     + (f"; no layer in {', '.join(f['no_layer'])}" if f["no_layer"] else ""))
    for fit in result.levels:
        for name in fit.parameters:
            lines.append(f"{name} = {fit.estimates[name]!r}  # - [derived] level {fit.level}: fit to "
                         f"{', '.join(fit.runs)}, standard error {fit.standard_errors[name]:.3g}")
    if result.spread:
        sp = result.spread
        lines.append(f"spread_core_share = {sp['value']!r}  # - [derived] the geometric mean of R* / R over the "
                     f"whole runs the regime rule spreads, {', '.join(sp['runs'])} (plume_force.csv), standard error "
                     f"{sp['standard_error']:.3g}")
    if result.stir:
        r, d = result.stir["radius"], result.stir["dispersion"]
        for key, regime in (("channel_collision_radius", "compact"), ("spread_channel_collision_radius", "spread")):
            if r[regime] is not None:
                lines.append(f"{key} = {r[regime]['value']!r}  # m [derived] the geometric mean of the collision "
                             f"radius R_eq / sqrt(S) over the {regime} whole runs {', '.join(r[regime]['runs'])} "
                             f"(analysis.channel_clustering at the fit's start radii), standard error "
                             f"{r[regime]['standard_error']:.3g}"
                             + (f"; S <= 1, not pooled: {', '.join(excluded)}"
                                if (excluded := [x for x in r["excluded"] if r["per_run"][x]["regime"] == regime])
                                else ""))
        lines.append(f"outer_dispersion = {d['value']!r}  # m^2/s [derived] the inverse-variance mean of 1 / D_e "
                     f"over {', '.join(d['runs'])} (analysis.suspension), standard error {d['standard_error']:.3g}"
                     + (f"; undetermined in {', '.join(d['undetermined'])}" if d["undetermined"] else ""))
    for key, value in CLOSURES[result.closures].get("form", FORM).items():
        lines.append(f"{key.split('.', 1)[1]} = {_q(value)}  # [chosen] the closure form of every level")
    for key, value in CLOSURES[result.closures].get("switches", {}).items():
        shown = _q(value) if isinstance(value, str) else str(value).lower()
        lines.append(f"{key.split('.', 1)[1]} = {shown}  # [chosen] closures = {result.closures!r}: "
                     f"{SWITCH_NOTES[key]}")
    lines += ["", "[provenance]", f"command = {_q(command or 'settler calibrate --set')}",
              f"code_commit = {_q(commit['commit'])}", f"code_tree_dirty = {str(bool(commit['dirty'])).lower()}",
              f"date = {_q(datetime.date.today().isoformat())}", f"registry = {_q(_portable(registry_path))}",
              f"gate_passed = {str(result.gate_passed).lower()}", f"closures = {_q(result.closures)}"]
    for level, runs in result.missing.items():
        lines.append(f"not_stored_{level} = [{', '.join(_q(r) for r in runs)}]  # [derived] registered, not run yet")
    lines += ["", "[provenance.collision]", f"efficiency = {c['efficiency']!r}  # - [derived]",
              f"standard_error = {c['standard_error']!r}  # - [derived]",
              f"quadrature_error = {c['quadrature_error']!r}  # - [derived] part of the standard error",
              f"merges = {c['merges']}  # - [derived] of the two fed sizes' bins",
              f"expected_collisions = {c['expected_collisions']!r}  # - [derived] at efficiency 1"]
    fitted = {name for fit in result.levels for name in fit.parameters} | {"collision_efficiency"}
    measured = {k: v for k, v in result.values.items() if k not in fitted}
    if measured:  # measured before the fit, with their own standard errors: the bands draw them too
        lines += ["", "[provenance.measured]"]
        lines += [f"{key} = [{_float(value)}, {_float(se)}]  # {PARAMETERS[key][2] if key in PARAMETERS else '?'} "
                  "[derived] value, standard error" for key, (value, se) in measured.items()]
    for fit in result.levels:
        lines += ["", f"[provenance.{fit.level}]",
                  f"runs = [{', '.join(_q(r) for r in fit.runs)}]  # [derived] the level's fitted runs",
                  f"chi2 = {fit.chi2!r}  # - [derived] for {fit.residual_count} residuals",
                  f"discrepancy = {fit.discrepancy!r}  # - [derived] relative model discrepancy added to every sigma",
                  f"model_runs = {fit.evaluations}  # - [derived]", f"status = {_q(fit.status)}",
                  f"gate_passed = {str(fit.gate['passed']).lower()}",
                  f"gate_reasons = [{', '.join(_q(r) for r in fit.gate['reasons'])}]  # [derived] empty: passed"]
        for i, name in enumerate(fit.parameters):
            prof = fit.profiles.get(name, {})
            lines.append(f"{name} = [{fit.estimates[name]!r}, {fit.standard_errors[name]!r}, "
                         f"{_float(prof.get('lower'))}, {_float(prof.get('upper'))}]  # - [derived] estimate, "
                         "standard error, profile 95 % interval (nan: open)")
            lines.append(f"correlation_{name} = [{', '.join(repr(round(float(v), 4)) for v in fit.correlation[i])}]"
                         "  # - [derived] in the order of the level's parameters")
        for run, errors in fit.errors.items():
            lines.append(f"error_{run} = [{', '.join(_float(errors[k]) for k in errors)}]  # - [derived] "
                         f"reduced / full - 1 of {', '.join(errors)}")
    lines += ["", "[provenance.holdouts]"]
    if result.holdout_errors is None:
        lines.append("scored = false  # the gate did not pass: no hold-out was scored")
    else:
        lines.append("scored = true")
        for run, errors in result.holdout_errors.items():
            lines.append(f"error_{run} = [{', '.join(_float(errors[k]) for k in errors)}]  # - [derived] "
                         f"reduced / full - 1 of {', '.join(errors)}")
        c = result.coverage or {}
        if c:
            lines.append(f"band_coverage = {c['share']!r}  # - [derived] {c['inside']} of {c['total']} hold-out "
                         f"window means inside their 90 % bands ({c['samples']} popbal runs each)")
            for run, columns in c["bands"].items():
                for column, q in columns.items():
                    lines.append(f"band_{run}_{column} = [{', '.join(repr(v) for v in q)}]  # [derived] 5, 50 and "
                                 "95 % of the window mean")
    return "\n".join(lines) + "\n"


def write_layer(result: Hierarchy, path, registry_path, command: str = "") -> Path:
    """Write :func:`layer_text` to ``path`` (a .toml file) atomically."""
    path = Path(path)
    if path.suffix != ".toml":
        raise OutputError(f"--write {path}: allowed: a .toml file (e.g. data/calibration/designed.toml)")
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, layer_text(result, registry_path, command))
    return path


def _git(repository: Path, *args):
    """git ``args`` in ``repository`` (subprocess.CompletedProcess, text), or None where git cannot be run."""
    import subprocess

    try:
        return subprocess.run(["git", "-C", str(repository), *args], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None


def fitted_set_engine(code_commit: str, repository: Path) -> dict | None:
    """The reference set's engine that a layer was fitted to: the ``[set]`` table of ``data/reference/engines.toml``
    at the layer's recorded ``code_commit``, read with git from ``repository`` (a checkout's root); None where git,
    the history or that file is not at hand (a shallow clone, an installed package). A layer whose set engine is not
    the stored set's was fitted to runs that are no longer stored, and its recorded errors and bands are not to be
    read against today's runs."""
    import tomllib

    shown = _git(repository, "show", f"{code_commit}:data/reference/engines.toml")
    if shown is None or shown.returncode != 0:
        return None
    try:
        return tomllib.loads(shown.stdout).get("set")
    except tomllib.TOMLDecodeError:
        return None


#: The commit from which the hold-outs' bands run popbal at each parameter draw (757f27c, 2026-12-07): before it every
#: draw was overridden by the estimates, and a layer's recorded bands and band_coverage are those of the discrepancy
#: term alone.
BANDS_DRAW_FROM = "757f27c0133f5a06ef4aac9e170b481a9d663f18"


def bands_draw_parameters(code_commit: str, repository: Path) -> bool | None:
    """Whether a layer written at ``code_commit`` drew its hold-out bands over the parameters (its commit descends
    from :data:`BANDS_DRAW_FROM`), False where it drew them over the discrepancy alone, None where git or the history
    is not at hand (a shallow clone, an installed package)."""
    done = _git(repository, "merge-base", "--is-ancestor", BANDS_DRAW_FROM, code_commit)
    return None if done is None else {0: True, 1: False}.get(done.returncode)
