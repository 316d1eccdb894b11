"""What the seed paper (Jylhä & Jokilaakso, Heliyon 9 (2023) e21570) states in numbers that its figures show, so
that our figures draw them beside our runs. Only values its text or tables state are here; nothing is read off a
plot. Each carries where it is stated.
"""

from __future__ import annotations

#: Steady droplet counts of section 4.1: "These steady state numbers are 125 000 and 130 000 droplets for the cubic
#: model and the simple model, respectively." Case name -> count [-].
STEADY_COUNT = {"cubic": 125_000.0, "simple": 130_000.0}
STEADY_COUNT_SOURCE = "seed §4.1"

#: Matte densities of the reaction runs, fresh to fully reacted [kg/m^3] (seed Table 3; the paper steps the droplets
#: through materials 50 kg/m^3 apart within it): the range of Fig. 20's density axis.
DENSITY_RANGE = (4500.0, 5200.0)
DENSITY_RANGE_SOURCE = "seed Table 3"

#: The coalescence size limits of the paper's cases [m] (section 3.3.1, Table 3); Fig. 11's mean diameter grows
#: towards the limit. The limit drawn is the run's own (``coalescence.size_limit`` of its case.toml), which for the
#: presets is this one.
SIZE_LIMIT = {"simple": 1.5e-3, "cubic": 2.0e-3, "deep": 40.0e-3}
SIZE_LIMIT_SOURCE = "seed §3.3.1"

#: How the paper's values are drawn: a dashed dark red line or a light band, labelled "paper: ...".
STYLE = {"color": "darkred", "linestyle": "--", "linewidth": 1.2}
BAND_STYLE = {"color": "darkred", "alpha": 0.08}


def steady_count(case_name: str) -> float | None:
    """The paper's steady droplet count of the case named ``case_name`` ('simple', 'cubic'), else None."""
    return STEADY_COUNT.get(case_name)


def draw_steady_count(ax, case_name: str) -> bool:
    """A horizontal line at the paper's steady count of ``case_name`` on ``ax`` (droplets [-] up); False if the paper
    states none for it."""
    count = steady_count(case_name)
    if count is None:
        return False
    ax.axhline(count, label=f"paper: ≈ {count:,.0f} steady ({STEADY_COUNT_SOURCE})".replace(",", " "), **STYLE)
    return True


def draw_size_limit(ax, limit: float, scale: float = 1e3, unit: str = "mm") -> bool:
    """A horizontal line at the coalescence size limit ``limit`` [m] (drawn times ``scale``, in ``unit``) on ``ax``
    when it lies within three times the axis' current top, else a note in the corner that it is off the scale;
    returns whether the line was drawn."""
    bottom, top = ax.get_ylim()
    value = scale * limit
    if value <= 3.0 * top:
        ax.axhline(value, label=f"size limit {value:g} {unit} ({SIZE_LIMIT_SOURCE})", **STYLE)
        return True
    ax.text(0.99, 0.03, f"size limit {value:g} {unit} (off the scale)", transform=ax.transAxes, ha="right",
            va="bottom", fontsize="small", color=STYLE["color"])
    return False


def draw_density_range(ax, vertical: bool = True) -> None:
    """The band of the paper's matte densities (:data:`DENSITY_RANGE`) on ``ax``: across the y axis when
    ``vertical`` (density up), else across x."""
    low, high = DENSITY_RANGE
    label = f"paper: matte {low:g}–{high:g} kg/m³, fresh to reacted ({DENSITY_RANGE_SOURCE})"
    (ax.axhspan if vertical else ax.axvspan)(low, high, label=label, **BAND_STYLE)
