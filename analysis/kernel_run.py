"""The collision efficiency of the reference set's kernel run: two droplet sizes settling in a closed box without
feed, their merges (``merges_by_size.csv``) over the gravitational collisions pi (a_i + a_j)^2 abs(U_i - U_j) n_i n_j V
predicts, integrated over the snapshots in horizontal slices (SI units). The first level of popbal's hierarchical
calibration takes its collision efficiency from here alone. Re-exported by :mod:`analysis.evidence`.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pandas as pd


def pair_exposure(snapshots, small: tuple[float, float], large: tuple[float, float], area: float,
                  slice_height: float) -> dict:
    """sum over snapshots of sum over horizontal slices of N_small N_large / V_slice, and the mean settling
    velocities of the two size ranges, for ``snapshots`` [(time [s], droplets DataFrame with z, diameter,
    settling_velocity)], size ranges [m] (low, high], a box of horizontal ``area`` [m^2] sliced ``slice_height``
    [m]: {"times", "exposure" (per snapshot) [1/m^3], "velocity_small", "velocity_large" (per snapshot) [m/s]}."""
    times, exposure, u_small, u_large = [], [], [], []
    for time, frame in snapshots:
        d = frame["diameter"].to_numpy()
        z = frame["z"].to_numpy()
        k = np.floor(z / slice_height).astype(np.int64)
        is_small = (d > small[0]) & (d <= small[1])
        is_large = (d > large[0]) & (d <= large[1])
        size = int(k.max()) + 1 if len(k) else 1
        n_small = np.bincount(k[is_small], minlength=size)
        n_large = np.bincount(k[is_large], minlength=size)
        exposure.append(float((n_small * n_large).sum()) / (area * slice_height))
        u_small.append(float(frame["settling_velocity"].to_numpy()[is_small].mean()) if is_small.any() else math.nan)
        u_large.append(float(frame["settling_velocity"].to_numpy()[is_large].mean()) if is_large.any() else math.nan)
        times.append(float(time))
    return {"times": np.array(times), "exposure": np.array(exposure), "velocity_small": np.array(u_small),
            "velocity_large": np.array(u_large)}


def collision_efficiency(merges: int, exposure: dict, diameter_small: float, diameter_large: float) -> dict:
    """E = merges / (pi (a_s + a_l)^2 integral abs(U_l - U_s) C dt) with C = sum N_s N_l / V over slices
    (:func:`pair_exposure`), trapezoidal over the snapshots.

    Droplets placed at rest (a snapshot whose two mean velocities are both exactly 0: the initial state) reach their
    terminal velocity within the particle relaxation time rho_p d^2 / (18 mu), about 1 ms here, so such a snapshot
    takes the velocity difference of the next one; with 0 the first interval would count half its collisions.
    Standard error: the Poisson count (sqrt M / M), the standard error of the mean velocity difference over the
    snapshots and the time quadrature (the change of E when every second snapshot is dropped, a first-order
    estimate of the error of the trapezoidal rule at the snapshots' spacing), in quadrature. Returns {"efficiency",
    "standard_error", "quadrature_error", "expected_collisions", "merges", "velocity_difference" [m/s]}."""
    t = np.asarray(exposure["times"], dtype=float)
    u_small = np.asarray(exposure["velocity_small"], dtype=float)
    u_large = np.asarray(exposure["velocity_large"], dtype=float)
    du = np.abs(u_large - u_small)
    at_rest = (u_small == 0.0) & (u_large == 0.0)
    for i in np.flatnonzero(at_rest)[::-1]:
        later = [j for j in range(i + 1, len(du)) if not at_rest[j] and np.isfinite(du[j])]
        if later:
            du[i] = du[later[0]]
    c = np.asarray(exposure["exposure"], dtype=float)
    good = np.isfinite(du) & np.isfinite(c)
    cross = math.pi * (0.5 * (diameter_small + diameter_large)) ** 2
    rate = np.where(good, cross * np.nan_to_num(du) * c, 0.0)
    expected = _trapezoid(rate, t)
    efficiency = merges / expected if expected > 0 else math.nan
    half = sorted(set(range(0, len(t), 2)) | {len(t) - 1})
    coarse = _trapezoid(rate[half], t[half]) if len(t) > 2 else math.nan
    quadrature = abs(merges / coarse - efficiency) if coarse > 0 else math.nan
    weights = c[good]
    mean_du = float(np.average(du[good], weights=weights)) if weights.sum() > 0 else math.nan
    du_error = float(np.std(du[good], ddof=1) / math.sqrt(good.sum())) if good.sum() > 1 else math.nan
    relative = math.sqrt((1.0 / merges if merges > 0 else math.inf) + (du_error / mean_du) ** 2)
    statistical = efficiency * relative
    return {"efficiency": efficiency, "standard_error": math.hypot(statistical, np.nan_to_num(quadrature)),
            "quadrature_error": quadrature, "expected_collisions": expected, "merges": int(merges),
            "velocity_difference": mean_du}


def _trapezoid(y, x) -> float:
    return float(np.trapezoid(y, x)) if hasattr(np, "trapezoid") else float(np.trapz(y, x))


def _bin_of(diameter: float, edges: np.ndarray) -> tuple[float, float]:
    """The merges-by-size bin (low, high] [m] that holds ``diameter`` (edges of fulldem's SIZE_BINS)."""
    bounds = np.concatenate([[0.0], edges, [np.inf]])
    b = int(np.searchsorted(edges, diameter, side="right"))
    return float(bounds[b]), float(bounds[b + 1])


#: The kernel run's exposure over every droplet snapshot of its run folder, stored beside the reference (the
#: reference keeps a few snapshots only; E needs them all): time [s], exposure [1/m^3], velocity_small and
#: velocity_large [m/s], and the run's merges of the pair in the units line's header.
EXPOSURE_FILE = "kernel_exposure.csv"
EXPOSURE_UNITS = {"time": ("s", "snapshot time"), "exposure": ("1/m^3", "sum over slices of N_s N_l / V_slice"),
                  "velocity_small": ("m/s", "mean settling velocity of the small size"),
                  "velocity_large": ("m/s", "mean settling velocity of the large size")}


def kernel_exposure(run_folder, diameter_small: float = 0.5e-3, diameter_large: float = 1.0e-3,
                    slice_height: float | None = None) -> tuple[pd.DataFrame, int, dict]:
    """(the :func:`pair_exposure` table over every droplet snapshot of a kernel run folder, the merges between the
    merges-by-size bins of the two fed sizes, {"small": bin, "large": bin} [m]); slices of one cell height unless
    ``slice_height`` [m]."""
    from fulldem.submodels.coalescence import SIZE_BINS

    from settler.cases import load_case

    from .files import droplets_file, snapshot_files

    folder = Path(run_folder)
    if not (folder / "merges_by_size.csv").is_file():
        raise ValueError(f"{folder}: no merges_by_size.csv (a kernel run has coalescence on)")
    case = load_case(folder / "case.toml")
    small, large = _bin_of(diameter_small, SIZE_BINS), _bin_of(diameter_large, SIZE_BINS)
    table = pd.read_csv(folder / "merges_by_size.csv", comment="#")
    pair = table[np.isclose(table["small_low"], small[0]) & np.isclose(table["large_low"], large[0])]
    snapshots = [(t, droplets_file(path)) for t, path, _ in snapshot_files(folder) if path is not None]
    exposure = pair_exposure(snapshots, small, large, case.geometry.width * case.geometry.depth,
                             slice_height or case.fulldem.cell_size)
    frame = pd.DataFrame({"time": exposure["times"], "exposure": exposure["exposure"],
                          "velocity_small": exposure["velocity_small"], "velocity_large": exposure["velocity_large"]})
    return frame, int(pair["merges"].sum()), {"small": small, "large": large}


def fed_sizes(droplets_csv) -> tuple[float, float]:
    """(small, large) diameter [m] of a kernel run's initial droplet list (x, y, z, diameter rows with a header):
    its two distinct diameters; ValueError if it holds another number of sizes."""
    diameters = np.unique(pd.read_csv(droplets_csv, comment="#")["diameter"].to_numpy(dtype=float))
    if diameters.size != 2:
        raise ValueError(f"{droplets_csv}: {diameters.size} droplet sizes; a kernel run has two")
    return float(diameters[0]), float(diameters[1])


def write_kernel_exposure(run_folder, dest, diameter_small: float = 0.5e-3, diameter_large: float = 1.0e-3) -> Path:
    """Write :data:`EXPOSURE_FILE` of the kernel run folder ``run_folder`` into the folder ``dest`` (atomically),
    for the fed sizes ``diameter_small`` and ``diameter_large`` [m], which its header records."""
    from settler.output import atomic_write_text, units_line

    frame, merges, bins = kernel_exposure(run_folder, diameter_small, diameter_large)
    small, large = bins["small"], bins["large"]
    header = (units_line(EXPOSURE_UNITS) + f"# merges: {merges} between ({small[0]:.9g}, {small[1]:.9g}] "
              f"and ({large[0]:.9g}, {large[1]:.9g}] m; sizes {diameter_small:g} and "
              f"{diameter_large:g} m\n")
    path = Path(dest) / EXPOSURE_FILE
    atomic_write_text(path, header + frame.to_csv(index=False, float_format="%.9g"))
    return path


def kernel_run_efficiency(run_folder, diameter_small: float | None = None, diameter_large: float | None = None,
                          slice_height: float | None = None) -> dict:
    """The collision efficiency of a kernel run (two sizes settling without feed; the reference set's 'kernel'):
    the merges between the bins of the two fed sizes (``merges_by_size.csv``) over the gravitational collisions of
    :func:`collision_efficiency`, with the exposure and velocities from every droplet snapshot of the run folder,
    or from its :data:`EXPOSURE_FILE` where the folder is a stored reference (each size counted within its
    merges-by-size bin; slices of one cell height unless ``slice_height`` [m]). The fed sizes: as given, else the
    sizes the stored file's header records, else 0.5 and 1.0 mm (the 'kernel' run's).
    Returns the result of :func:`collision_efficiency` plus "bins", "snapshots" and "sizes"."""
    stored = Path(run_folder) / EXPOSURE_FILE
    if stored.is_file() and slice_height is None:
        frame = pd.read_csv(stored, comment="#")
        head = [line for line in stored.read_text().splitlines()[:3] if line.startswith("# merges:")]
        numbers = re.findall(r"[-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?", head[0].split(":", 1)[1])
        merges = int(numbers[0])
        bins = {"small": (float(numbers[1]), float(numbers[2])), "large": (float(numbers[3]), float(numbers[4]))}
        if diameter_small is None and len(numbers) >= 7:  # "...; sizes A and B m"
            diameter_small, diameter_large = float(numbers[5]), float(numbers[6])
    else:
        diameter_small = 0.5e-3 if diameter_small is None else diameter_small
        diameter_large = 1.0e-3 if diameter_large is None else diameter_large
        frame, merges, bins = kernel_exposure(run_folder, diameter_small, diameter_large, slice_height)
    exposure = {"times": frame["time"].to_numpy(), "exposure": frame["exposure"].to_numpy(),
                "velocity_small": frame["velocity_small"].to_numpy(),
                "velocity_large": frame["velocity_large"].to_numpy()}
    diameter_small = 0.5e-3 if diameter_small is None else diameter_small
    diameter_large = 1.0e-3 if diameter_large is None else diameter_large
    result = collision_efficiency(merges, exposure, diameter_small, diameter_large)
    result.update(bins=bins, snapshots=len(frame), sizes=(diameter_small, diameter_large))
    return result
