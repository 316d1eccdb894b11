"""Sweep axes: ``section.key=v1,v2,...``, ``a:b:n[:log]`` or a single fixed value, each checked against the case
schema (see :mod:`analysis.sweep`, *Axes*).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from settler.cases import SCHEMA, Case, CaseError, case_with_overrides, parse_override


@dataclass(frozen=True)
class Axis:
    """One swept case key. ``values``: the listed or spaced values (None for a bare range ``a:b``); ``low``,
    ``high``: the range of ``a:b[:n]`` (None for a list); ``log``: spaced / sampled on a log scale."""

    key: str
    spec: str
    values: tuple | None
    low: float | None = None
    high: float | None = None
    log: bool = False

    @property
    def unit(self) -> str:
        section, name = self.key.split(".")
        return SCHEMA[section][name].unit

    @property
    def fixed(self) -> bool:
        """A single value: a fixed override, not a swept axis."""
        return self.values is not None and len(self.values) == 1

    @property
    def is_range(self) -> bool:
        return self.low is not None


def _field(key: str):
    """The schema field of ``section.key``; CaseError naming the key and the allowed keys otherwise."""
    section, dot, name = key.partition(".")
    if not dot or section not in SCHEMA:
        raise CaseError(f"sweep axis {key!r}: not a section.key of the case; allowed sections: " + ", ".join(SCHEMA))
    if name not in SCHEMA[section]:
        raise CaseError(f"sweep axis {key!r}: unknown key {key}; allowed keys in [{section}]: "
                        + ", ".join(SCHEMA[section]))
    return SCHEMA[section][name]


def _number(key: str, text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise CaseError(f"sweep axis {key}: {what} {text!r} is not a number; allowed: a:b:n or a:b:n:log with "
                        "numbers a, b and an integer n >= 1") from None
    if not math.isfinite(value):
        raise CaseError(f"sweep axis {key}: {what} {text!r}: allowed: a finite number")
    return value


def _spaced(key: str, spec: str, kind: type) -> tuple[tuple | None, float, float, bool]:
    """(values, a, b, log) of ``a:b[:n[:lin|log]]``; values None without n."""
    parts = spec.split(":")
    scale = "lin"
    if len(parts) == 4:
        scale = parts.pop().strip().lower()
        if scale not in ("lin", "log"):
            raise CaseError(f"sweep axis {key} = {spec!r}: scale {scale!r}; allowed: lin or log (a:b:n:log)")
    if len(parts) not in (2, 3):
        raise CaseError(f"sweep axis {key} = {spec!r}: allowed: a:b:n (n values from a to b, linear), "
                        "a:b:n:log (logarithmic) or v1,v2,...")
    low, high = _number(key, parts[0], "a"), _number(key, parts[1], "b")
    log = scale == "log"
    if log and not (low > 0.0 and high > 0.0):
        raise CaseError(f"sweep axis {key} = {spec!r}: a log scale needs a > 0 and b > 0")
    if len(parts) == 2:
        return None, low, high, log
    try:
        count = int(parts[2])
    except ValueError:
        count = 0
    if count < 1:
        raise CaseError(f"sweep axis {key} = {spec!r}: n = {parts[2]!r}; allowed: an integer >= 1")
    values = np.geomspace(low, high, count) if log else np.linspace(low, high, count)
    if kind is int:
        rounded = np.round(values)
        if np.any(np.abs(values - rounded) > 1e-9 * np.maximum(1.0, np.abs(values))):
            raise CaseError(f"sweep axis {key} = {spec!r}: {key} takes integers, and these values are not "
                            f"({', '.join(f'{v:g}' for v in values)}); choose n so that they are, or list them")
        return tuple(int(v) for v in rounded), low, high, log
    return tuple(float(v) for v in values), low, high, log


def _listed(key: str, spec: str) -> tuple:
    """The values of ``v1,v2,...``: read as a TOML array (numbers, booleans, lists), else split at commas and each
    read as an override value (settler.cases.parse_override: TOML, else a string)."""
    import tomllib

    try:
        values = tomllib.loads(f"v = [{spec}]")["v"]
    except tomllib.TOMLDecodeError:
        values = [parse_override(f"{key}={item}")[1] for item in spec.split(",")]
    if not values or any(v == "" for v in values):
        raise CaseError(f"sweep axis {key} = {spec!r}: an empty value; allowed: v1,v2,... or a:b:n")
    return tuple(values)


def parse_axis(text: str, base: Case | None = None) -> Axis:
    """An :class:`Axis` from ``section.key=SPEC`` (see the module docstring). With ``base``, every value is
    validated on it (CaseError naming the key, the value and what is allowed)."""
    key, eq, spec = (t.strip() for t in text.partition("="))
    if not eq or not spec:
        raise CaseError(f"sweep axis {text!r}: allowed: section.key=v1,v2,... or section.key=a:b:n[:log]")
    spec_field = _field(key)
    if ":" in spec and not spec.lstrip().startswith(("[", '"', "'")):
        if spec_field.kind not in (float, int):
            raise CaseError(f"sweep axis {key} = {spec!r}: a range a:b:n needs a numeric key; {key} takes "
                            f"{spec_field.allowed()}: list its values v1,v2,...")
        values, low, high, log = _spaced(key, spec, spec_field.kind)
        axis = Axis(key, spec, values, low, high, log)
    else:
        values = _listed(key, spec)
        if len(set(map(repr, values))) != len(values):
            raise CaseError(f"sweep axis {key} = {spec!r}: a value is listed twice; allowed: distinct values")
        axis = Axis(key, spec, values)
    if base is not None:
        for value in axis.values or (axis.low, axis.high):
            if spec_field.kind is int and isinstance(value, float):
                value = round(value)
            try:
                case_with_overrides(base, {key: value})
            except CaseError as exc:
                raise CaseError(f"sweep axis {key}: {exc}") from None
    return axis


def parse_axes(axes, base: Case | None = None) -> list[Axis]:
    """Axes from a list of ``section.key=SPEC`` strings, or a dict key -> SPEC string or list of values."""
    if isinstance(axes, dict):
        texts = [f"{k}={v}" if isinstance(v, str) else f"{k}={','.join(_toml_item(x) for x in v)}"
                 for k, v in axes.items()]
    else:
        texts = list(axes)
    parsed = [parse_axis(t, base) for t in texts]
    keys = [a.key for a in parsed]
    repeated = sorted({k for k in keys if keys.count(k) > 1})
    if repeated:
        raise CaseError(f"sweep axis {repeated[0]}: given more than once; allowed: one axis per key")
    return parsed


def _toml_item(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_item(v) for v in value) + "]"
    return repr(float(value)) if isinstance(value, float) else repr(value)
