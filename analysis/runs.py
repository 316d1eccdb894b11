"""Loading a run of either engine, or a stored reference run, from its folder: :func:`load_run`.

A run folder is what ``settler full CASE --out RUN`` (engine ``fulldem``) or ``settler reduced CASE --out RUN``
(engine ``popbal``) writes; a stored reference is a ``data/reference/<case>/`` folder written by
:mod:`analysis.reference` (a full run kept small). :func:`load_run` reads what every comparison needs at once and
the rest when asked (SI units throughout):

=============================  =========================================================================================
:attr:`Run.timeseries`         ``timeseries.csv`` as a DataFrame (columns of :data:`settler.output.TIME_SERIES`)
:attr:`Run.units`              column -> unit, from the CSV's ``# units:`` line (else metadata.json, else TIME_SERIES)
:attr:`Run.engine`             ``"fulldem"``, ``"popbal"`` or None (not recorded and not told by the files present)
:attr:`Run.metadata`           ``metadata.json`` (a reference keeps it inside ``reference.json``), or None
:attr:`Run.reference`          ``reference.json`` of a stored reference, else None
:attr:`Run.merges_by_size`     ``merges_by_size.csv`` (full engine with coalescence), or None
:attr:`Run.channel_profile`    ``channel_profile.csv``, or None
:attr:`Run.zones`              the zone diagnostics of a full run (:data:`settler.output.SNAPSHOT_TABLES`): ``{"zone_profile":
                               ..., "zones": ..., "lift_by_size": ...}`` DataFrames of the files present (empty: none)
:attr:`Run.case`               the resolved case of ``case.toml`` (:class:`settler.cases.Case`), read when first used
:meth:`Run.droplets`,          a full run's droplet and slag snapshots (the ``.vtu`` files of ``snapshots.pvd``, or a
:meth:`Run.slag`               reference's ``snapshots.npz``), read on demand through :mod:`analysis.figures`' readers
:meth:`Run.distribution`       popbal's size distribution (``distribution.npz``) as an xarray Dataset with dims
                               time, zone, z, section; units in each variable's ``units`` attribute
:meth:`Run.timeseries_dataset` the time series as an xarray Dataset (dim time; units in attrs)
=============================  =========================================================================================

:func:`write_netcdf` writes such a Dataset as compressed netCDF-4 (engine h5netcdf, zlib level
:data:`NETCDF_COMPLEVEL`) atomically; :func:`read_netcdf` reads it back with the units as written (no time
decoding: a ``units = "s"`` variable stays a float in seconds).

This module reads files only; it imports no engine (popbal is imported only to name the distribution arrays of an
old run whose metadata.json does not list them).
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pandas as pd

from settler.output import (TIME_SERIES, OutputError, atomic_write_bytes, read_channel_profile, read_time_series,
                            round_times)

from .files import read_json, read_zone_tables


#: Engine names as ``metadata.json`` records them.
FULL_ENGINE = "fulldem"
REDUCED_ENGINE = "popbal"
#: zlib compression level of :func:`write_netcdf` (1 fastest .. 9 smallest).
NETCDF_COMPLEVEL = 4
#: Dimension of each letter in the shape note that opens a distribution array's meaning ("(T, Z, J, K) ..."),
#: as popbal.DISTRIBUTION_ARRAYS writes them.
SHAPE_LETTERS = {"T": "time", "Z": "zone", "J": "z", "K": "section", "X": "path"}

_UNITS_LINE = re.compile(r"(\w+) \[([^\]]*)\]")
_SHAPE_NOTE = re.compile(r"^\(([A-Z](?:,\s*[A-Z])*),?\)\s*")


@dataclasses.dataclass
class Run:
    """A run of either engine, or a stored reference, read by :func:`load_run`. SI units throughout."""

    folder: Path
    engine: str | None
    timeseries: pd.DataFrame
    units: dict[str, str]
    metadata: dict | None
    reference: dict | None
    merges_by_size: pd.DataFrame | None
    channel_profile: pd.DataFrame | None
    zones: dict = dataclasses.field(default_factory=dict)
    _cache: dict = dataclasses.field(default_factory=dict, repr=False)

    def __repr__(self) -> str:
        times = self.timeseries["time"]
        span = f"t = {times.iloc[0]:g}–{times.iloc[-1]:g} s" if len(times) else "no rows"
        kind = "stored reference" if self.is_reference else f"{self.engine or 'unknown engine'} run"
        return (f"<Run {self.folder.name!r}: {kind}, {len(times)} time-series rows ({span}), "
                f"{len(self.timeseries.columns)} columns, folder {str(self.folder)!r}>")

    @property
    def is_reference(self) -> bool:
        """True for a stored ``data/reference/<case>/`` folder (it holds reference.json)."""
        return self.reference is not None

    @property
    def name(self) -> str:
        """The case's name from case.toml, else the folder's name."""
        try:
            name = getattr(self.case.case, "name", None)
        except (OutputError, ValueError, OSError):
            name = None
        return name or self.folder.resolve().name

    @property
    def case(self):
        """The resolved case (:class:`settler.cases.Case`) of the run's ``case.toml``, read on first use. Raises
        OutputError if the run has no case.toml, settler.cases.CaseError if it cannot be read."""
        if "case" not in self._cache:
            from settler.cases import load_case

            path = self.folder / "case.toml"
            if not path.is_file():
                raise OutputError(f"{path}: missing; the run's resolved case is not stored")
            self._cache["case"] = load_case(path)
        return self._cache["case"]

    # ----------------------------------------------------------------------------------------------- snapshots
    def snapshot_times(self) -> np.ndarray:
        """Times [s] of the droplet snapshots a full run or reference holds (empty for popbal runs)."""
        if self.is_reference:
            return np.asarray(self._stored_reference().snapshot_times, dtype=float)
        from .files import snapshot_files

        return np.array([t for t, droplets, _ in snapshot_files(self.folder) if droplets is not None], dtype=float)

    def droplets(self, time=None) -> tuple[float, pd.DataFrame]:
        """The droplets of the snapshot nearest ``time`` [s] (None: the last): (its time [s], DataFrame with x, y, z
        [m], diameter [m], u, v, w and settling_velocity [m/s], density [kg/m^3], age [s], merged [-]), as
        :func:`analysis.figures.read_droplets` reads them. Raises analysis.files.NoData where there are none
        (popbal runs have none: use :meth:`distribution`)."""
        from .figures import read_droplets
        from .files import NoData

        self._need_snapshots(NoData)
        return read_droplets(self.folder, time)

    def slag(self, time=None) -> tuple[float, np.ndarray, np.ndarray]:
        """The slag of the snapshot nearest ``time`` [s] (None: the last): (its time [s], cell centres (n, 3) [m],
        velocity (n, 3) [m/s]); a reference keeps the central x-z plane only. See
        :func:`analysis.figures.read_slag`."""
        from .figures import read_slag
        from .files import NoData

        self._need_snapshots(NoData)
        return read_slag(self.folder, time)

    def _need_snapshots(self, error):
        if self.engine == REDUCED_ENGINE:
            raise error(f"{self.folder}: a popbal run has no droplet or slag snapshots; its size distribution is "
                        "Run.distribution()")

    def _stored_reference(self):
        if "stored" not in self._cache:
            from analysis.reference import load_reference

            self._cache["stored"] = load_reference(self.folder.name, self.folder.parent)
        return self._cache["stored"]

    # ------------------------------------------------------------------------------------------------ datasets
    def timeseries_dataset(self):
        """The time series as an xarray Dataset (see :func:`time_series_dataset`)."""
        return time_series_dataset(self.timeseries, self.units, attrs=self._dataset_attrs("timeseries.csv"))

    def distribution(self):
        """popbal's size distribution (``distribution.npz``) as an xarray Dataset, read on first use (see
        :func:`distribution_dataset`). Raises OutputError if the run has none (full-engine runs and references
        keep droplets, not a distribution: :meth:`droplets`)."""
        if "distribution" not in self._cache:
            path = self.folder / "distribution.npz"
            if not path.is_file():
                raise OutputError(f"{path}: missing; only a popbal run ('settler reduced') has a size distribution"
                                  + ("" if self.engine == REDUCED_ENGINE else
                                     f" (this is a {self.engine or 'run of unknown engine'}: see Run.droplets)"))
            try:
                with np.load(path) as data:
                    arrays = {k: data[k] for k in data.files}
            except (OSError, ValueError) as exc:
                raise OutputError(f"{path}: cannot be read ({type(exc).__name__}: {exc})") from None
            meta = self.metadata or {}
            self._cache["distribution"] = distribution_dataset(
                arrays, _distribution_descriptions(meta), zones=meta.get("zones"),
                attrs=self._dataset_attrs("distribution.npz"))
        return self._cache["distribution"]

    def to_netcdf(self, path, part: str = "distribution") -> Path:
        """Write :meth:`distribution` (``part="distribution"``) or :meth:`timeseries_dataset` (``"timeseries"``)
        to ``path`` as compressed netCDF (:func:`write_netcdf`); returns the path."""
        parts = {"distribution": self.distribution, "timeseries": self.timeseries_dataset}
        if part not in parts:
            raise ValueError(f"part = {part!r}: allowed: " + ", ".join(parts))
        return write_netcdf(parts[part](), path)

    def _dataset_attrs(self, source: str) -> dict:
        meta = self.metadata or {}
        case = self.folder / "case.toml"
        return {"engine": self.engine or "unknown", "run_folder": str(self.folder.resolve()), "source_file": source,
                "commit": str(meta.get("commit") or (self.reference or {}).get("commit") or "unknown"),
                **({"settler_case": case.read_text(encoding="utf-8")} if case.is_file() else {})}


# ------------------------------------------------------------------------------------------------------ loading
def load_run(folder) -> Run:
    """The run of either engine, or stored reference, in ``folder`` (see the module docstring for what it holds).

    Raises :class:`settler.output.OutputError` with a one-line message naming the folder or file: no such folder, a
    file instead of a folder, no ``timeseries.csv`` (not a run), an unreadable time series or JSON file. A folder
    that is already a :class:`Run` is returned as it is.
    """
    if isinstance(folder, Run):
        return folder
    folder = Path(folder)
    if not folder.is_dir():
        raise OutputError(f"{folder}: no such run folder" if not folder.exists()
                          else f"{folder}: is a file, not a run folder")
    series_path = folder / "timeseries.csv"
    if not series_path.is_file():
        raise OutputError(f"{folder}: not a run folder (no timeseries.csv); give the --out folder of 'settler full' "
                          "or 'settler reduced', or a stored data/reference/<case> folder")
    try:
        series = read_time_series(series_path)
    except (OSError, ValueError) as exc:  # pandas raises ValueError subclasses for a damaged CSV
        raise OutputError(f"{series_path}: cannot be read ({type(exc).__name__}: {' '.join(str(exc).split())})") \
            from None
    if "time" not in series:
        raise OutputError(f"{series_path}: has no time column; not a time series of settler.output")
    reference = read_json(folder / "reference.json")
    metadata = read_json(folder / "metadata.json")
    if metadata is None and isinstance(reference, dict) and isinstance(reference.get("metadata"), dict):
        metadata = reference["metadata"]
    optional = {name: round_times(read_channel_profile(folder / name)) if (folder / name).is_file() else None
                for name in ("merges_by_size.csv", "channel_profile.csv")}  # both plain CSV (+ a units line)
    # times rounded to the nanosecond (runs written before the writers rounded them): selectable by output time
    return Run(folder=folder, engine=_engine(folder, metadata), timeseries=round_times(series),
               units=time_series_units(series_path, metadata), metadata=metadata, reference=reference,
               merges_by_size=optional["merges_by_size.csv"], channel_profile=optional["channel_profile.csv"],
               zones={name: round_times(table) for name, table in read_zone_tables(folder).items()})



def _engine(folder: Path, metadata) -> str | None:
    """The engine that made the run: metadata.json's "engine", else told by the files only one engine writes."""
    if isinstance(metadata, dict) and metadata.get("engine"):
        return str(metadata["engine"])
    if (folder / "distribution.npz").is_file():
        return REDUCED_ENGINE
    if any((folder / name).is_file() for name in ("snapshots.pvd", "checkpoint.npz", "snapshots.npz")):
        return FULL_ENGINE
    return None


def time_series_units(path, metadata=None) -> dict[str, str]:
    """Column -> unit of a ``timeseries.csv``: its ``# units:`` line (``name [unit], ...``) first, then metadata's
    ``time_series_units``, then :data:`settler.output.TIME_SERIES` (columns it does not know get no entry)."""
    units = {c: u for c, (u, _) in TIME_SERIES.items()}
    if isinstance(metadata, dict) and isinstance(metadata.get("time_series_units"), dict):
        units.update({str(k): str(v) for k, v in metadata["time_series_units"].items()})
    with open(path, encoding="utf-8") as fh:
        first = fh.readline()
    if first.startswith("#") and "units" in first:
        units.update(dict(_UNITS_LINE.findall(first)))
    return units


# ----------------------------------------------------------------------------------------------------- datasets
def time_series_dataset(frame: pd.DataFrame, units: dict[str, str], attrs: dict | None = None):
    """A time series as an xarray Dataset: dim ``time`` (the ``time`` column [s]), one variable per other column,
    each with ``units`` (from ``units``; "unknown" where not given) and ``long_name`` (the meaning in
    :data:`settler.output.TIME_SERIES`, where it has one)."""
    import xarray as xr

    def var_attrs(column):
        out = {"units": units.get(column, "unknown")}
        if column in TIME_SERIES:
            out["long_name"] = TIME_SERIES[column][1]
        return out

    time = frame["time"].to_numpy(dtype=float)
    data = {c: ("time", frame[c].to_numpy(dtype=float), var_attrs(c)) for c in frame.columns if c != "time"}
    return xr.Dataset(data, coords={"time": ("time", time, var_attrs("time"))}, attrs=dict(attrs or {}))


def _distribution_descriptions(metadata: dict) -> dict[str, tuple[str, str]]:
    """name -> (unit, meaning) of the distribution arrays: metadata.json's ``distribution_arrays`` (written by popbal
    since it has them), else popbal.DISTRIBUTION_ARRAYS (the engine's public table)."""
    listed = metadata.get("distribution_arrays") if isinstance(metadata, dict) else None
    if isinstance(listed, dict) and listed:
        return {k: (str(v.get("unit", "unknown")), str(v.get("meaning", ""))) for k, v in listed.items()}
    from popbal import DISTRIBUTION_ARRAYS

    return dict(DISTRIBUTION_ARRAYS)


def array_dims(name: str, meaning: str) -> tuple[str, ...]:
    """The dims of a distribution array from the shape note opening its meaning: ``"(T, Z, J, K) droplets per
    m^3"`` -> (time, zone, z, section) (letters of :data:`SHAPE_LETTERS`). Raises OutputError without one."""
    match = _SHAPE_NOTE.match(meaning)
    letters = [p.strip() for p in match.group(1).split(",")] if match else []
    if not letters or any(letter not in SHAPE_LETTERS for letter in letters):
        raise OutputError(f"distribution array {name}: its description {meaning!r} does not open with a shape note "
                          f"such as '(T, Z, J, K)'; letters allowed: " + ", ".join(SHAPE_LETTERS))
    return tuple(SHAPE_LETTERS[letter] for letter in letters)


def distribution_dataset(arrays: dict, descriptions: dict[str, tuple[str, str]], zones=None, attrs=None):
    """popbal's size distribution as an xarray Dataset with dims time, zone, z, section.

    ``arrays``: name -> array (the content of distribution.npz); ``descriptions``: name -> (unit, meaning), each
    meaning opening with its shape note (:func:`array_dims`); ``zones``: the zone names (default: 0, 1, ...).
    A 1-D array named like its dim (``time`` [s], ``z`` [m]) is that dim's coordinate; other 1-D arrays
    (``zone_area`` [m^2], ``original_volume`` [m^3], ``original_diameter`` [m]) are coordinates along their dim;
    ``section`` is numbered 0 .. K-1. Every variable carries ``units`` and ``long_name`` attributes. An array
    without a description, or whose shape disagrees with its dims, raises OutputError naming it.
    """
    import xarray as xr

    sizes: dict[str, int] = {}
    dims_of = {}
    for name, values in arrays.items():
        if name not in descriptions:
            raise OutputError(f"distribution array {name}: not described (allowed: " + ", ".join(descriptions) + ")")
        dims = array_dims(name, descriptions[name][1])
        shape = np.shape(values)
        if len(shape) != len(dims):
            raise OutputError(f"distribution array {name}: shape {shape} does not match its dims {dims}")
        for dim, size in zip(dims, shape):
            if sizes.setdefault(dim, size) != size:
                raise OutputError(f"distribution array {name}: {dim} has {size} entries, other arrays {sizes[dim]}")
        dims_of[name] = dims

    def var(name):
        unit, meaning = descriptions[name]
        return dims_of[name], np.asarray(arrays[name]), {"units": unit, "long_name": _SHAPE_NOTE.sub("", meaning)}

    coords = {name: var(name) for name, dims in dims_of.items() if len(dims) == 1}
    data = {name: var(name) for name, dims in dims_of.items() if len(dims) > 1}
    if "section" in sizes:
        coords["section"] = ("section", np.arange(sizes["section"]), {"units": "-", "long_name": "section index"})
    if "zone" in sizes:
        names = list(zones) if zones is not None and len(zones) == sizes["zone"] else list(range(sizes["zone"]))
        coords["zone"] = ("zone", np.asarray([str(z) for z in names]), {"long_name": "zone"})
    if "path" in sizes:  # the return flow's paths between zones (popbal.driver.EXCHANGES)
        from popbal.driver import EXCHANGES

        names = list(EXCHANGES) if len(EXCHANGES) == sizes["path"] else list(range(sizes["path"]))
        coords["path"] = ("path", np.asarray([str(p) for p in names]), {"long_name": "path between zones"})
    return xr.Dataset(data, coords=coords, attrs=dict(attrs or {}))


# ------------------------------------------------------------------------------------------------------- netCDF
def write_netcdf(dataset, path, complevel: int = NETCDF_COMPLEVEL) -> Path:
    """Write ``dataset`` to ``path`` as netCDF-4 through h5netcdf with CF-1.10 attributes (:func:`analysis.cf.apply`:
    UDUNITS units, axis attributes, the case embedded when the dataset's ``settler_case`` holds it), every numeric
    variable zlib-compressed at ``complevel``, atomically (built in memory, then
    :func:`settler.output.atomic_write_bytes`). Returns the path."""
    from . import cf

    title = f"settler {dataset.attrs.get('engine', '')} {dataset.attrs.get('source_file', 'run')}".replace("  ", " ")
    dataset = cf.apply(dataset.copy(deep=False), title=title, case_toml=dataset.attrs.get("settler_case"))
    encoding = {name: {"zlib": True, "complevel": int(complevel)}
                for name, variable in dataset.variables.items() if variable.dtype.kind in "fiub"}
    data = dataset.to_netcdf(path=None, engine="h5netcdf", encoding=encoding)
    path = Path(path)
    atomic_write_bytes(path, bytes(data))
    return path


def read_netcdf(path):
    """A Dataset written by :func:`write_netcdf`, loaded into memory (the file is closed), values and attributes as
    written: no time or timedelta decoding (``units = "s"`` stays seconds)."""
    import xarray as xr

    with xr.open_dataset(path, engine="h5netcdf", decode_times=False, decode_timedelta=False) as dataset:
        return dataset.load()
