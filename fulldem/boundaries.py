"""One description of the box's boundaries -- walls, the inlet on the top face, the outlet on a side wall -- from
which the fluid, the feed, the exits and the contacts all take theirs.

Side codes (one encoding everywhere): :data:`SIDES` maps the case's ``geometry.outlet_side`` names to codes 0-3;
a side's wall is normal to axis ``code // 2`` (0: x, 1: y) and is that axis's upper wall when ``code % 2 == 1``.
On an outlet's wall, ``transverse`` is the coordinate along the wall (y on x walls, x on y walls) and ``height`` the
z coordinate of the disk's centre [m].

To add a boundary: describe it here (a NamedTuple built by :func:`boundaries_for`) and give each consumer its
form as a method, as :class:`Outlet` does for the fluid (:meth:`Outlet.fluid_disk`), the exits
(:meth:`Outlet.exit_args`) and the contact walls (:meth:`Outlet.contact_args`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


#: Side codes of a side wall, by the case file's name (geometry.outlet_side).
SIDES = {"x-": 0, "x+": 1, "y-": 2, "y+": 3}
SIDE_NAMES = {code: name for name, code in SIDES.items()}


def side_axis(code: int) -> int:
    """Axis normal to side ``code`` (0: x, 1: y)."""
    return int(code) // 2


def side_is_upper(code: int) -> bool:
    """Whether side ``code`` is the upper wall of its axis (x+, y+)."""
    return int(code) % 2 == 1


class InletDisk(NamedTuple):
    """A velocity inlet on the top wall: disk centre (x, y) [m] and radius [m]."""

    centre: tuple[float, float]
    radius: float


class OutletDisk(NamedTuple):
    """A mass-balanced outflow disk on a side wall.

    side: 'x-', 'x+', 'y-' or 'y+'; centre: (transverse, height) [m], transverse = y on x walls, x on y walls,
    height = z; radius [m].
    """

    side: str
    centre: tuple[float, float]
    radius: float


class Inlet(NamedTuple):
    """The feed area on the top face: centre (x, y) [m], radius [m], top z [m], and ``length`` [m]: 0 for a disk
    of that radius, else a slot (rectangle) ``length`` long along x and 2 ``radius`` wide along y."""

    centre: tuple[float, float]
    radius: float
    top: float
    length: float = 0.0

    @property
    def is_slot(self) -> bool:
        return self.length > 0.0

    @property
    def half_extent(self) -> tuple[float, float]:
        """Half the feed area's extent along x and y [m] (the disk's radius twice for a disk)."""
        return (0.5 * self.length if self.is_slot else self.radius, self.radius)

    @property
    def area(self) -> float:
        """The feed area [m^2]."""
        return self.length * 2.0 * self.radius if self.is_slot else float(np.pi) * self.radius**2

    def contains(self, x, y):
        """Whether points (x, y) [m] lie within the disk's radius of its axis (a slot: inside its rectangle)."""
        if self.is_slot:
            return ((np.abs(np.asarray(x) - self.centre[0]) <= 0.5 * self.length)
                    & (np.abs(np.asarray(y) - self.centre[1]) <= self.radius))
        return (np.asarray(x) - self.centre[0]) ** 2 + (np.asarray(y) - self.centre[1]) ** 2 <= self.radius**2


class Outlet(NamedTuple):
    """The outflow disk on a side wall: side code (see :data:`SIDES`), centre (transverse, height) [m], radius [m]
    and the wall's plane coordinate along its axis [m]."""

    side: int
    transverse: float
    height: float
    radius: float
    plane: float

    @property
    def side_name(self) -> str:
        return SIDE_NAMES[self.side]

    def fluid_disk(self):
        """The fluid solver's form (:class:`fulldem.boundaries.OutletDisk`)."""

        return OutletDisk(self.side_name, (self.transverse, self.height), self.radius)

    def exit_args(self) -> tuple:
        """(side, plane, transverse, height, radius): the arguments of :func:`fulldem.submodels.exits.classify_exits`."""
        return (self.side, self.plane, self.transverse, self.height, self.radius)

    def contact_args(self) -> tuple:
        """(side, height, transverse, radius): the DEM stepper's ``outlet`` (no wall force over the disk)."""
        return (self.side, self.height, self.transverse, self.radius)


#: No outlet, in the exits' form.
NO_OUTLET_EXIT_ARGS = (-1, 0.0, 0.0, 0.0, 0.0)


class Boundaries(NamedTuple):
    """The box [lower, upper] [m], its periodic axes, the inlet disk (where droplets are fed), whether slag flows in
    through it (``slag_inlet``, at ``inflow_flux`` [m^3/s]), the outlet (None where absent) and whether droplets
    touching the bottom leave as settled."""

    lower: np.ndarray
    upper: np.ndarray
    periodic: np.ndarray
    inlet: Inlet
    slag_inlet: bool
    inflow_flux: float
    outlet: Outlet | None
    absorbing_bottom: bool

    def fluid_inlet(self):
        """The fluid solver's velocity inlet (:class:`fulldem.boundaries.InletDisk`), or None without slag inflow."""

        if self.slag_inlet and self.inlet.is_slot:
            raise ValueError("a slot inlet feeds matte only: no slag inflow through it (settler.cases refuses "
                             "slag.feed_rate > 0 with geometry.inlet_length)")
        return InletDisk(self.inlet.centre, self.inlet.radius) if self.slag_inlet else None

    def fluid_outlet(self):
        """The fluid solver's outflow disk (:class:`fulldem.boundaries.OutletDisk`), or None."""
        return self.outlet.fluid_disk() if self.outlet is not None else None

    def contact_outlet(self):
        """The DEM stepper's ``outlet`` argument, or None."""
        return self.outlet.contact_args() if self.outlet is not None else None

    def exit_args(self) -> tuple:
        """(bottom, side, plane, transverse, height, radius) for :func:`fulldem.submodels.exits.classify_exits` (bottom
        -inf where the bottom does not absorb)."""
        bottom = float(self.lower[2]) if self.absorbing_bottom else -np.inf
        return (bottom, *(self.outlet.exit_args() if self.outlet is not None else NO_OUTLET_EXIT_ARGS))


def boundaries_for(case, lower, upper, periodic, *, slag_inlet=True, outlet=True,
                   absorbing_bottom=True) -> Boundaries:
    """The boundaries of a case's box [lower, upper]: the inlet disk of geometry.inlet_diameter (a slot
    geometry.inlet_length by inlet_diameter where the length is given) at the case's inlet centre on the top face, with the slag feed (slag.feed_rate) flowing in if ``slag_inlet``; the outlet disk of
    geometry.outlet_diameter centred across its wall at geometry.outlet_height if ``outlet``."""
    g = case.geometry
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    the_inlet = Inlet(tuple(case.inlet_center), 0.5 * g.inlet_diameter, float(upper[2]),
                      float(g.inlet_length) if g.inlet_length is not None else 0.0)
    the_outlet = None
    if outlet:
        side = SIDES[g.outlet_side]
        axis = side_axis(side)
        transverse = 0.5 * (g.depth if axis == 0 else g.width)
        plane = float(upper[axis] if side_is_upper(side) else lower[axis])
        the_outlet = Outlet(side, transverse, g.outlet_height, 0.5 * g.outlet_diameter, plane)
    inflow = case.slag.feed_rate / case.slag.density if slag_inlet else 0.0
    return Boundaries(lower, upper, np.asarray(periodic, dtype=np.bool_), the_inlet, bool(slag_inlet), inflow,
                      the_outlet, bool(absorbing_bottom))
