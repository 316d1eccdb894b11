"""The seed paper's figures (Jylhä & Jokilaakso, Heliyon 9 (2023) e21570) drawn from a stored run folder.

A run folder is what ``settler full CASE --out RUN`` writes (SI units throughout): ``timeseries.csv`` (columns of
:data:`settler.output.TIME_SERIES`), ``snapshots.pvd`` listing ``droplets_NNNNN.vtu`` (part 0) and
``fluid_NNNNN.vti`` (part 1; ``.vtu`` hexahedra in older runs) per snapshot time, ``channel_profile.csv``, ``case.toml`` and ``metadata.json``.
This module reads those files only (pandas, NumPy, meshio, matplotlib); it never imports an engine, so it works on
a machine where none is built, on a finished run, a stopped one or one still running.

One function per figure returns a :class:`matplotlib.figure.Figure` (made without pyplot, so drawing needs no
display and no backend is switched; files are written by the Agg canvas). Each takes ``ax=``: the caller's Axes
(a sequence of them for a figure of several panels) to draw into, so that runs can be overlaid or placed in a
figure of one's own; ``label=`` names the run in the legend. Where the seed paper states a value the figure shows
(the steady counts, the size limits, the range of matte densities: :mod:`analysis.figures.paper`), it is drawn
beside ours.

=================================  =====================================================================  ===========
function                           what                                                                   seed paper
=================================  =====================================================================  ===========
:func:`droplet_counts`             total, coalesced and never-coalesced droplets vs time                  Fig. 15
:func:`centre_diameter_velocity`   mean diameter and centreline settling velocity vs time                 Fig. 11
:func:`settling_velocity`          mean settling velocity vs time                                         Fig. 16
:func:`slice_droplets`             droplets in a thin slab around the central x-z plane, coloured by      Figs. 8, 9,
                                   diameter or downward speed                                             12, 17, 18
:func:`slice_slag`                 slag speed and in-plane arrows on the central x-z plane                Fig. 10
:func:`density_height`             every droplet's density vs its height                                  Fig. 20
:func:`velocity_height`            every droplet's downward speed vs its height                           Fig. 21
:func:`channel`                    channel radius and axis velocity vs time, and vs height                (ours)
=================================  =====================================================================  ===========

:func:`render_all` writes them all as PNG, PDF or SVG files (``settler figures RUN --out DIR [--format F]`` calls
it). A figure whose inputs
are missing (an old or partial run, a snapshot without droplets, a column that is all NaN) raises :class:`NoData`
with a one-line reason; :func:`render_all` records that reason and goes on with the others.

Snapshot figures take ``time`` [s]: the snapshot nearest to it is drawn (default: the last one); the title gives
the snapshot's own time. The central plane is y = the inlet centre's y (``geometry.inlet_center`` of ``case.toml``,
default the middle of the depth).
"""

from __future__ import annotations

import argparse
import io
import xml.etree.ElementTree as ET
from pathlib import Path

from settler.output import atomic_write_bytes

from ..files import NoData, check_run, snapshot_files
from . import paper
from .inputs import axes, read_droplets, read_slag
from .series import centre_diameter_velocity, channel, droplet_counts, settling_velocity, zones
from .snapshots import (QUIVER_ARROWS, SLAB_DEPTH_FRACTION, SLAB_DIAMETERS, density_height, slab,
                        slab_half_thickness, slice_droplets, slice_slag, velocity_height)

__all__ = ["FIGURE_FILES", "FORMATS", "NoData", "centre_diameter_velocity", "channel", "density_height",
           "droplet_counts", "figure_functions", "paper", "read_droplets", "read_slag", "render_all",
           "settling_velocity", "slab", "slab_half_thickness", "slice_droplets", "slice_slag", "velocity_height",
           "zones", "axes", "QUIVER_ARROWS", "SLAB_DEPTH_FRACTION", "SLAB_DIAMETERS"]

#: The files :func:`render_all` writes: figure name -> file name in PNG (the seed paper's figure number where it has
#: one); another format replaces the suffix.
FIGURE_FILES = {
    "droplet_counts": "fig15_droplet_counts.png",
    "centre_diameter_velocity": "fig11_centre_diameter_velocity.png",
    "settling_velocity": "fig16_settling_velocity.png",
    "slice_diameter": "slice_diameter.png",
    "slice_velocity": "slice_velocity.png",
    "slice_slag": "fig10_slice_slag.png",
    "density_height": "fig20_density_height.png",
    "velocity_height": "fig21_velocity_height.png",
    "channel": "channel.png",
    "zones": "zones.png",
}
#: Resolution of the PNGs of :func:`render_all` [dots per inch].
DPI = 120
#: The formats :func:`render_all` and ``settler figures --format`` write (matplotlib's writers).
FORMATS = ("png", "pdf", "svg")


# ------------------------------------------------------------------------------------------------------ all of them
def figure_functions(time=None) -> dict:
    """Figure name (key of :data:`FIGURE_FILES`) -> a function of the run folder that draws it (snapshot figures at
    the snapshot nearest ``time`` [s], None: the last)."""
    return {
        "droplet_counts": droplet_counts,
        "centre_diameter_velocity": centre_diameter_velocity,
        "settling_velocity": settling_velocity,
        "slice_diameter": lambda run: slice_droplets(run, time, "diameter"),
        "slice_velocity": lambda run: slice_droplets(run, time, "velocity"),
        "slice_slag": lambda run: slice_slag(run, time),
        "density_height": lambda run: density_height(run, time),
        "velocity_height": lambda run: velocity_height(run, time),
        "channel": lambda run: channel(run, time),
        "zones": zones,
    }


def render_all(run, out_dir, time=None, format="png") -> dict[str, Path | str]:  # noqa: A002 -- matplotlib's name
    """Draw every figure of the run folder ``run`` and write it in ``format`` (one of :data:`FORMATS`; PNG at
    :data:`DPI`) into ``out_dir`` (created), named as in :data:`FIGURE_FILES`; snapshot figures at the snapshot
    nearest ``time`` [s] (None: the last).

    Returns figure name -> the written path, or -> the one-line reason it was skipped (its inputs are missing or
    unreadable). Raises FileNotFoundError if ``run`` is not a run folder (no timeseries.csv and no snapshots.pvd).
    """
    if format not in FORMATS:
        raise ValueError(f"format = {format!r}: allowed: {', '.join(FORMATS)}")
    run = check_run(run)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results: dict[str, Path | str] = {}
    for name, draw in figure_functions(time).items():
        try:
            fig = draw(run)
        except NoData as exc:
            results[name] = str(exc)
            continue
        except (OSError, ValueError, KeyError, ET.ParseError) as exc:  # an unreadable file of a partial run
            text = " ".join(str(exc).split())
            results[name] = f"an input could not be read ({type(exc).__name__}: {text[:160]})"
            continue
        buffer = io.BytesIO()
        fig.savefig(buffer, format=format, dpi=DPI)
        fig.clear()  # made without pyplot: nothing to close, release its artists
        path = out_dir / Path(FIGURE_FILES[name]).with_suffix("." + format)
        atomic_write_bytes(path, buffer.getvalue())
        results[name] = path
    return results


# ------------------------------------------------------------------------------------------------ command line
def _finite_time(text):
    """--time: a finite number of seconds (argparse refuses anything else with exit status 2)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give a snapshot time in seconds") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"{text!r}: give a finite snapshot time in seconds")
    return value


def add_arguments(parser):
    """The arguments of ``settler figures`` (registered in :data:`settler.cli.TOOLS`)."""
    parser.add_argument("run", help="the output folder of a 'settler full' run (holding timeseries.csv and/or "
                                    "snapshots.pvd)")
    parser.add_argument("--out", metavar="DIR", default=None, help="folder to write the figures into (default: "
                                                                  "RUN/figures; created if missing)")
    parser.add_argument("--format", choices=FORMATS, default="png",
                        help="file format of the figures (default: png, at 120 dots per inch)")
    parser.add_argument("--time", metavar="T", type=_finite_time, default=None,
                        help="snapshot time [s] of the snapshot figures: the nearest snapshot is drawn (default: "
                             "the last)")


def main(args) -> int:
    """``settler figures RUN [--out DIR] [--time T] [--format F]``: every figure as a file; the exit status."""
    from settler.output import OutputError, prepare_output_folder

    try:
        run = check_run(args.run)
    except FileNotFoundError as exc:  # not a run: refused input (exit 2), not a failed run
        raise OutputError(str(exc)) from None
    # resume=True: only the checks (a file, not writable); the folder may hold anything, the run itself included
    out = prepare_output_folder(args.out if args.out is not None else Path(run) / "figures", resume=True)
    try:
        times = [t for t, _, _ in snapshot_files(run)] if args.time is not None else []
    except NoData:  # an unreadable snapshots.pvd: render_all says so for each snapshot figure
        times = []
    if times:
        nearest = min(times, key=lambda t: (abs(t - args.time), -t))
        if nearest != args.time:
            print(f"snapshot figures at t = {nearest:g} s, the snapshot nearest --time {args.time:g}")
    results = render_all(run, out, time=args.time, format=args.format)
    width = max(len(name) for name in results)
    for name, result in results.items():
        print(f"{name:<{width}s}  {result}" if isinstance(result, Path) else f"{name:<{width}s}  skipped: {result}")
    if not any(isinstance(result, Path) for result in results.values()):
        raise OutputError(f"{run}: no figure could be drawn (reasons above)")
    return 0
