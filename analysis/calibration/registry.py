"""The pre-registered hold-outs, families and levels of popbal's calibration (``data/calibration/holdouts.toml``).

A hold-out named there is never fitted, never used to choose a closure, and is scored once, after the
identifiability gate has passed; :func:`refuse_holdouts` is the one check every fit goes through.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from settler.cases import DATA_DIR, CaseError, _read_toml

#: The registry shipped with the toolkit.
REGISTRY = DATA_DIR / "calibration" / "holdouts.toml"
LEVELS = ("collision", "transport", "whole")


class RegistryError(ValueError):
    """A registry that cannot be used, or a fit that would use a hold-out; the message names the file and key."""


@dataclass(frozen=True)
class Registry:
    """holdouts: run names never fitted, with why; families: {family: runs} for leave-one-family-out; levels:
    {level: runs} of the hierarchical fit (:data:`LEVELS`); path: the file read; left_out: the family's runs a
    cross-validation fold holds out (:func:`leave_family_out`; among ``holdouts`` too), else empty."""

    holdouts: tuple[str, ...]
    why: dict[str, str]
    families: dict[str, tuple[str, ...]]
    levels: dict[str, tuple[str, ...]]
    path: Path
    left_out: tuple[str, ...] = ()


def load_registry(path: str | Path = REGISTRY) -> Registry:
    """Read and check a registry file (see ``data/calibration/holdouts.toml``)."""
    path = Path(path)
    try:
        raw = _read_toml(path, "hold-out registry")  # the project's TOML reader and its one-line refusals
    except CaseError as exc:
        raise RegistryError(str(exc)) from None
    holdouts = tuple(raw.get("holdouts", {}).get("runs", ()))
    why = dict(raw.get("holdouts", {}).get("why", {}))
    families = {k: tuple(v) for k, v in raw.get("families", {}).items()}
    levels = {k: tuple(v) for k, v in raw.get("levels", {}).items()}
    if not holdouts:
        raise RegistryError(f"{path}: [holdouts] runs is empty; allowed: at least one run name")
    unexplained = [h for h in holdouts if not why.get(h)]
    if unexplained:
        raise RegistryError(f"{path}: [holdouts.why] has no reason for {', '.join(unexplained)}; every hold-out "
                            "states why it was chosen")
    unknown = [k for k in levels if k not in LEVELS]
    if unknown:
        raise RegistryError(f"{path}: [levels] {', '.join(unknown)}: allowed levels {', '.join(LEVELS)}")
    registry = Registry(holdouts=holdouts, why=why, families=families, levels=levels, path=path)
    for where, names in [*(("[families] " + k, v) for k, v in families.items()),
                         *(("[levels] " + k, v) for k, v in levels.items())]:
        refuse_holdouts(names, registry, where)
    return registry


def refuse_holdouts(names, registry: Registry | None = None, where: str = "the fit", reference_dir=None) -> None:
    """Raise :class:`RegistryError` if any of ``names`` is a pre-registered hold-out of ``registry`` (default: the
    shipped one): by name, by the last part of a path given for it ("deep/", "./deep_fine"), and, with
    ``reference_dir``, by the folder it resolves to there (a link under another name)."""
    registry = registry or load_registry()

    def holdout_of(name) -> str | None:
        text = str(name)
        for holdout in registry.holdouts:
            if holdout in (text, Path(text).name) or (
                    reference_dir is not None
                    and (Path(reference_dir) / text).resolve() == (Path(reference_dir) / holdout).resolve()):
                return holdout
        return None

    used = [(str(n), holdout_of(n)) for n in names if holdout_of(n)]
    if used:
        name, holdout = used[0]
        shown = ", ".join(n if n == h else f"{n} ({h})" for n, h in used)
        raise RegistryError(f"{where}: {shown} is a pre-registered hold-out ({registry.path.name}: "
                            f"{registry.why[holdout].split(':')[0][:80]}...); allowed: runs not in "
                            f"{', '.join(registry.holdouts)}")


def refuse_holdout_folders(folders, registry: Registry | None = None, where: str = "the measure",
                           reference_dir="data/reference") -> None:
    """:func:`refuse_holdouts` for run folders given as paths (a measure on full runs, ``python -m
    analysis.channel_clustering`` and ``analysis.suspension``): by name and last part as there, and by the folder a
    path resolves to against each hold-out's folder under ``reference_dir`` (a link or copy path under another
    name)."""
    registry = registry or load_registry()
    refuse_holdouts(folders, registry, where)
    stored = {(Path(reference_dir) / h).resolve(): h for h in registry.holdouts}
    for folder in folders:
        holdout = stored.get(Path(folder).resolve())
        if holdout is not None:
            raise RegistryError(f"{where}: {folder} ({holdout}) is a pre-registered hold-out ({registry.path.name}); "
                                f"allowed: runs not in {', '.join(registry.holdouts)}")


def leave_family_out(registry: Registry, family: str) -> Registry:
    """The registry with one of its [families] held out as well (leave-one-family-out cross-validation): the
    family's runs (its coalescence-off variants listed with it) join the hold-outs (scored only after the gate, as
    the pre-registered ones) and leave every level. RegistryError for a family the registry does not name or one
    that would empty a level."""
    if family not in registry.families:
        raise RegistryError(f"--leave-out {family!r}: {registry.path.name} has no such family; allowed: "
                            + ", ".join(registry.families))
    runs = registry.families[family]
    why = {**registry.why, **{r: f"left out with family {family!r} for cross-validation" for r in runs}}
    levels = {k: tuple(r for r in v if r not in runs) for k, v in registry.levels.items()}
    emptied = [k for k, v in levels.items() if registry.levels[k] and not v]
    if emptied:
        raise RegistryError(f"--leave-out {family!r}: it takes every run of level {', '.join(emptied)} "
                            f"({registry.path.name}); allowed: a family that leaves each level a run")
    return Registry(holdouts=(*registry.holdouts, *runs), why=why, families=registry.families, levels=levels,
                    path=registry.path, left_out=tuple(runs))
