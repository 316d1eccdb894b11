"""A run set's reference runs: every finished run of a run-set sweep of the full engine stored small
(:func:`analysis.reference.store_reference`) under its run name, with what each run's own folder alone can measure:
the kernel runs' exposure (:mod:`analysis.kernel_run`), collisions by height (:mod:`analysis.band_efficiency`) and
what the return flow lifts off the floor (:mod:`analysis.floor_lift`), the matte layer over it
(:mod:`analysis.floor_layer`), where the droplets are across the plume (:mod:`analysis.plume_zones`) and the plume's
axis velocity against the Stokes flow they drive (:mod:`analysis.plume_force`). Command line::

    python -m analysis.reference_set SWEEP_OUT SET_FILE [--only a,b] [--dest data/reference] [--snapshots 2]

(It sits apart from :mod:`analysis.reference` because those measures read runs through :mod:`analysis.runs`, which
itself reads stored references.)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from analysis.reference import store_reference


def store_set(sweep_out, set_file, dest_root="data/reference", snapshots=2, only=None) -> dict[str, Path | str]:
    """Store every finished run of a run-set sweep of the full engine (``settler sweep --set SET_FILE --engine full
    --out SWEEP_OUT``; finished runs only, so this may run while the sweep goes on) as ``dest_root/<run name>/``,
    its command the one that regenerates it alone (``settler sweep --set SET_FILE --engine full --only NAME``),
    with the kernel runs' exposure (:mod:`analysis.kernel_run`), for runs with coalescence and a merge table their
    collisions by height (:data:`analysis.band_efficiency.COLLISIONS_FILE`), and for runs whose snapshots follow
    the droplets by ident what the return flow lifts off the floor (:data:`analysis.floor_lift.FLOOR_LIFT_FILE`),
    the matte layer over the floor by size (:data:`analysis.floor_layer.FLOOR_LAYER_FILE`) and the droplets of the
    plume's core, skirt and return flow by height (:data:`analysis.plume_zones.PLUME_ZONES_FILE`) and the axis velocity
    against the Stokes flow they drive (:data:`analysis.plume_force.PLUME_FORCE_FILE`), all measured on the run
    folder.
    ``snapshots`` is the droplet snapshots each run keeps where its entry in the set has no ``snapshots`` key. Returns
    name -> the stored folder, or -> why it was not stored (not finished)."""
    from analysis.sweep.execution import DONE_FILE, POINTS, point_hash
    from analysis.sweep.runset import load_run_set

    sweep_out = Path(sweep_out)
    wanted = None if only is None else set(only.split(",") if isinstance(only, str) else only)
    results: dict[str, Path | str] = {}
    for run in load_run_set(set_file).runs:
        if wanted is not None and run.name not in wanted:
            continue
        folder = sweep_out / POINTS / point_hash(run.case, "full", run.droplets)
        if not (folder / DONE_FILE).is_file():
            results[run.name] = f"not finished ({folder} has no {DONE_FILE})"
            continue
        command = f"settler sweep --set {set_file} --engine full --only {run.name}"
        keep = snapshots if run.snapshots is None else run.snapshots
        results[run.name] = store_reference(folder, run.name, dest_root=dest_root, snapshots=keep, command=command)
        if run.family == "kernel":  # E needs every snapshot's exposure; the reference keeps a few snapshots
            from analysis.kernel_run import fed_sizes, write_kernel_exposure

            sizes = fed_sizes(run.droplets) if run.droplets else (0.5e-3, 1.0e-3)
            write_kernel_exposure(folder, results[run.name], *sizes)
        if run.case.coalescence.enabled and (folder / "merges_by_height.csv").is_file():
            # the collisions by height need every snapshot in the window and the whole slag grid, which the
            # reference does not keep (analysis.band_efficiency); a run without a snapshot there goes without
            from analysis.band_efficiency import write_collisions

            try:
                write_collisions(folder, results[run.name])
            except ValueError:
                pass
        # what the return flow lifts off the floor, by size, needs the run's every snapshot (analysis.floor_lift);
        # a run whose snapshots carry no idents, or with fewer than two in its window, goes without
        from analysis.files import NoData
        from analysis.floor_lift import write_floor_lift

        try:
            write_floor_lift(folder, results[run.name])
        except (ValueError, NoData):
            pass
        # the matte layer over the floor, by size, from every droplet snapshot in the window (analysis.floor_layer)
        from analysis.floor_layer import write_floor_layer

        try:
            write_floor_layer(folder, results[run.name])
        except (ValueError, NoData):
            pass
        # where the droplets are at each height: the plume's core, its skirt and the return flow (analysis.plume_zones);
        # a kernel run has no feed and no plume, a slot inlet a row of plumes
        from analysis.plume_zones import write_plume_zones

        try:
            if run.family != "kernel":
                write_plume_zones(folder, results[run.name])
        except (ValueError, NoData):
            pass
        # the axis velocity against the confined Stokes flow the droplets drive, by height (analysis.plume_force)
        from analysis.plume_force import write_plume_force

        try:
            if run.family != "kernel":
                write_plume_force(folder, results[run.name])
        except (ValueError, NoData):
            pass
    return results


def main(argv=None) -> int:
    """``python -m analysis.reference_set SWEEP_OUT SET_FILE [--only a,b] [--dest DIR] [--snapshots N]``."""
    parser = argparse.ArgumentParser(prog="python -m analysis.reference_set",
                                     description="Store the finished runs of a run-set sweep of the full engine as "
                                                 "references, each under its run name.")
    parser.add_argument("sweep_out", help="the --out folder of 'settler sweep --set FILE --engine full'")
    parser.add_argument("--only", default=None, help="only these runs (comma-separated names)")
    parser.add_argument("--dest", default="data/reference", help="where references lie (default: data/reference)")
    parser.add_argument("--snapshots", type=int, default=2,
                        help="droplet snapshots per run where the set file gives the run none (its key 'snapshots'; "
                             "0 = none) (default: 2)")
    parser.add_argument("set_file", help="the run-set file of the sweep, as the stored commands should name it "
                                         "(e.g. data/reference/design.toml)")
    args = parser.parse_args(argv)
    try:
        results = store_set(args.sweep_out, args.set_file, args.dest, args.snapshots, args.only)
    except ValueError as exc:
        print(f"{parser.prog}: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    for name, result in results.items():
        print(f"{name}: {result}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
