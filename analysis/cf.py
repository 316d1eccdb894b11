"""CF conventions for the netCDF files the toolkit writes (run time series and size distributions, sweeps, run
sets): :func:`udunits` spells a unit of ours (``kg/m^3``, ``-``) as UDUNITS-2 does (``kg m-3``, ``1``), and
:func:`apply` gives a Dataset the attributes CF-1.10 asks for — ``Conventions``, ``title``, ``source``,
``history``, ``units`` in UDUNITS spelling on every numeric variable, ``axis``/``standard_name``/``positive`` on the
time and height coordinates — and embeds the resolved case (its TOML) as the ``settler_case`` attribute, so that
a file read alone says what made it. Pure attribute work, no engine imported.
"""

from __future__ import annotations

import datetime as _dt
import re

#: The CF version the attributes follow.
CONVENTIONS = "CF-1.10"
#: Units that mean "no unit" in our tables -> UDUNITS' dimensionless "1".
DIMENSIONLESS = {"-", "–", "", "1", "none", "dimensionless"}
#: Coordinates with CF axis attributes: name -> attributes.
AXES = {
    "time": {"axis": "T", "standard_name": "time"},
    "z": {"axis": "Z", "standard_name": "height", "positive": "up"},
}

#: Unit symbols :func:`udunits` accepts (those our tables use, and their SI relatives).
SYMBOLS = {"m", "s", "kg", "g", "K", "Pa", "J", "mol", "N", "W", "h", "min", "Hz", "rad", "L"}

_TOKEN = re.compile(r"^([A-Za-z]+)(?:\^?(-?\d+))?$")


def udunits(unit: str | None) -> str | None:
    """``unit`` as UDUNITS-2 writes it: ``"-"`` -> ``"1"``, ``"kg/m^3"`` -> ``"kg m-3"``, ``"m^3/s"`` ->
    ``"m3 s-1"``, ``"1/s"`` -> ``"s-1"``, ``"Pa s"`` -> ``"Pa s"``; None for a unit it cannot parse ("unknown",
    a free text), which the caller then leaves out rather than write a wrong one."""
    if unit is None:
        return None
    text = str(unit).strip()
    if text in DIMENSIONLESS:
        return "1"
    parts = text.replace("·", " ").replace("*", " ").split("/")
    if len(parts) > 2:
        return None
    out = []
    for sign, part in zip((1, -1), parts):
        tokens = part.split()
        if sign == -1 and not tokens:
            return None
        for token in tokens:
            if token == "1" and sign == 1 and len(tokens) == 1:
                continue  # "1/s"
            match = _TOKEN.match(token)
            if match is None or match.group(1) not in SYMBOLS:
                return None
            power = sign * int(match.group(2) or 1)
            out.append(match.group(1) + ("" if power == 1 else str(power)))
    return " ".join(out) if out else "1"


def apply(dataset, title: str, case_toml: str | None = None, source: str | None = None):
    """``dataset`` (an xarray Dataset, changed in place and returned) with CF-1.10 attributes: global
    ``Conventions``, ``title``, ``source`` (default: settler, its version and the dataset's ``engine``), ``history`` (what wrote it, when),
    ``settler_case`` (``case_toml``, if given); on every variable a ``units`` attribute in UDUNITS spelling (a unit
    :func:`udunits` cannot parse is moved to ``units_note`` and left out); on ``time`` and ``z`` the axis
    attributes of :data:`AXES`."""
    from settler import __version__

    for name, variable in dataset.variables.items():
        attrs = variable.attrs
        if variable.dtype.kind not in "fiu":
            attrs.pop("units", None)
            continue
        if "units" in attrs:
            spelled = udunits(attrs["units"])
            if spelled is None:
                attrs["units_note"] = str(attrs.pop("units"))
            else:
                attrs["units"] = spelled
        if name in AXES:
            attrs.update(AXES[name])
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    engine = dataset.attrs.get("engine")
    dataset.attrs.update(Conventions=CONVENTIONS, title=title,
                         source=source or f"settler {__version__}" + (f", engine {engine}" if engine else ""),
                         history=f"{stamp} written by settler {__version__}")
    if case_toml:
        dataset.attrs["settler_case"] = case_toml
    return dataset
