"""A single droplet settling in quiescent slag: the Stokes check of the tests (tests/test_fulldem_stepper.py) and
of the verification report (analysis.verification.stokes_check), against the drag law's terminal velocity times
the square-duct wall factor. Lengths in m, times in s, velocities in m/s.
"""

from __future__ import annotations

from settler.cases import load_case

from ..droplets import DropletStore
from ..stepper import Simulation


def single_droplet(diameter, box=(0.2, 0.2, 0.2), cell=0.01, fluid_step=5e-3, t_end=1.5, extra=()):
    """One droplet of ``diameter`` [m] (5100 kg/m^3) released 50 mm under the top of a closed box [m] of quiescent
    slag (the simple case's), run to ``t_end`` [s]; returns (the Simulation, its settling velocity [m/s])."""
    case = load_case("simple", ["feed.mass_rate=0", "coalescence.enabled=false", f"fulldem.cell_size={cell}",
                                f"fulldem.fluid_step={fluid_step}", *extra])
    store = DropletStore(16)
    store.add([[box[0] / 2, box[1] / 2, box[2] - 0.05]], diameter, 5100.0)
    sim = Simulation(case, droplets=store, feed=False, box=(box, (0.0, 0.0, 0.0)))
    while sim.time < t_end - 1e-12:
        sim.step()
    return sim, float(-store.velocity[0, 2])
