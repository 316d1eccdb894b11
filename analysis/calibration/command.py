"""``settler calibrate --set REGISTRY``: the hierarchical calibration from the command line (see
:mod:`analysis.calibration.hierarchy`). Prints the summary; ``--out DIR`` writes ``hierarchy.json`` and
``summary.txt`` there, ``--write TOML`` the calibration layer."""

from __future__ import annotations

from settler.output import OutputError, atomic_write_text, prepare_output_folder, to_json

from .hierarchy import calibrate_set
from .layer import write_layer
from .registry import RegistryError, leave_family_out, load_registry
from .zones import MeasureError


def run_set(args) -> int:
    """Run the hierarchy for parsed ``settler calibrate`` arguments; exit status 0 (2 via OutputError)."""
    if args.max_evaluations < 1:
        raise OutputError(f"--max-evaluations {args.max_evaluations!r}: allowed an integer >= 1")
    leave_out = getattr(args, "leave_out", None)
    samples = getattr(args, "band_samples", 20)
    if samples < 0 or samples in (1, 2, 3, 4):
        raise OutputError(f"--band-samples {samples!r}: allowed 0 (no bands) or an integer of at least 5")
    workers = getattr(args, "workers", 1)
    if workers < 1:
        raise OutputError(f"--workers {workers!r}: allowed an integer >= 1")
    training_only = getattr(args, "training_only", False)
    if training_only and args.write:
        raise OutputError(f"--write {args.write} with --training-only: a fit that scores no hold-out is a closure "
                          "set's trial on the training runs, not a calibration layer; allowed: --out DIR for its "
                          "results")
    no_profile = getattr(args, "no_profile", False)
    if no_profile and not training_only:
        raise OutputError("--no-profile without --training-only: a fit that may score the pre-registered hold-outs "
                          "checks its gate with the profile-likelihood intervals; allowed: --no-profile with "
                          "--training-only (a trial or a cross-validation fold)")
    if leave_out and args.write:
        raise OutputError(f"--write {args.write} with --leave-out {leave_out}: a cross-validation fit leaves runs out "
                          "on purpose and is not a calibration layer; allowed: --out DIR for its results")
    out = prepare_output_folder(args.out, overwrite=args.overwrite) if args.out else None
    try:
        registry = load_registry(args.set)
        if leave_out:
            registry = leave_family_out(registry, leave_out)
            print(f"calibrate: leaving out family {leave_out!r} ({', '.join(registry.families[leave_out])}): "
                  + ("scored below alone (--training-only)" if training_only
                     else "scored below with the pre-registered hold-outs"))
        result = calibrate_set(registry, args.reference_dir, max_evaluations=args.max_evaluations,
                               profile=not no_profile, progress=not args.quiet, band_samples=samples,
                               closures=getattr(args, "closures", "designed"), workers=workers,
                               training_only=training_only)
    except (RegistryError, FileNotFoundError) as exc:
        raise OutputError(str(exc)) from None
    except MeasureError as exc:  # a closure the fit's runs do not carry (a fold that leaves them out)
        fold = f" with family {leave_out!r} left out" if leave_out else ""
        raise OutputError(f"--closures {getattr(args, 'closures', 'designed')}{fold}: {exc}; allowed: a closure set "
                          "or fold whose fitted runs carry every measured closure") from None
    text = result.summary()
    print(text)
    if out is not None:
        data = {"closures": result.closures, "roof": result.roof, "floor": result.floor, "leave_out": leave_out,
                "training_only": training_only, "profile": not no_profile,
                "holdouts": list(registry.holdouts),
                "scored": list(result.holdout_errors or {}),  # the runs scored: none when the gate failed
                "collision": result.collision, "values": result.values,
                "radius_factor": result.radius_factor,
                "gate_passed": result.gate_passed, "holdout_errors": result.holdout_errors, "missing": result.missing,
                "coverage": result.coverage,
                "levels": [{k: v for k, v in fit.__dict__.items()} for fit in result.levels]}
        atomic_write_text(out / "hierarchy.json", to_json(data))
        atomic_write_text(out / "summary.txt", text + "\n")
        print(f"calibrate: wrote {out}/hierarchy.json, summary.txt")
    if args.write:
        path = write_layer(result, args.write, args.set, getattr(args, "command_line", ""))
        print(f"calibrate: wrote the calibration layer {path}")
    return 0
