"""The exits: droplets removed at the bottom (settled) and through the side outlet (lost), matte mass counted
exactly at every removal (the submodel is :class:`fulldem.submodels.base.Exits`).
"""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def classify_exits(position, diameter, count, bottom, outlet_side, outlet_plane, outlet_transverse, outlet_height,
                   outlet_radius, exit_code):
    """exit_code[p] = 1 if the droplet touches the bottom (settled), 2 if its centre is within one radius of the
    outlet wall inside the outlet disk (lost), else 0. outlet_side -1 means no outlet. Returns the number exiting."""
    n = 0
    for p in range(count):
        r = 0.5 * diameter[p]
        code = 0
        if position[p, 2] - r <= bottom:
            code = 1
        elif outlet_side >= 0:
            axis = 0 if outlet_side < 2 else 1
            other = 1 - axis
            if outlet_side % 2 == 0:
                near = position[p, axis] - r <= outlet_plane
            else:
                near = position[p, axis] + r >= outlet_plane
            if near:
                dt = position[p, other] - outlet_transverse
                dz = position[p, 2] - outlet_height
                if dt * dt + dz * dz <= outlet_radius * outlet_radius:
                    code = 2
        exit_code[p] = code
        if code:
            n += 1
    return n
