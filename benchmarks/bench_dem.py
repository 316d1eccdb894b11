"""DEM-only speed benchmark (shared/reference/benchmark-case.md): our Numba kernels against LIGGGHTS on one case.

    python benchmarks/bench_dem.py --n 130000 --case sparse            # ours (+ LIGGGHTS if installed)
    python benchmarks/bench_dem.py --n 10000 --case dense --no-liggghts

The case: 0.5 mm droplets (rho 5100 kg/m^3) resting on the floor at the centre of a closed 0.2 m cube, effective
gravity 9.81 (5100 - 3150)/5100 m/s^2, linear Stokes drag 3 pi 0.45 d in still slag, Hooke normal contacts
k_n = 5 N/m with gamma_n = 2358.5 1/s (F = k_n delta - m_eff gamma_n v_n; restitution 0.5 between droplets; the
walls use the same gamma_n with m_eff = m), step 2e-5 s, skin 0.25 d, 2000 steps. Starting states: *sparse*, a
random non-overlapping packing at volume fraction 0.30 in a cube sub-box; *dense*, a touching FCC bed. Both spatially
sorted. Throughput = droplets x steps / loop time (set-up and the first neighbour build excluded).

With --liggghts (default when ``liggghts`` or an ``lmp_*`` executable is on PATH) the same case is written as a
LIGGGHTS input script (benchmarks/liggghts/, same initial positions via a data file), run with
``mpirun --allow-run-as-root --oversubscribe -np 2``, and its "Loop time" and kinetic energies are printed beside
ours. The machine is shared with other processes: compare the ratio measured within one run, not absolute figures
across runs.

Our integrator treats the drag exactly (exponential step) while LIGGGHTS applies ``fix viscous`` explicitly inside
velocity Verlet; --drag explicit makes ours do the same (beta = 0, drag as a force from the half-step velocity) so the
kinetic energies can be compared digit by digit.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np
from numba import njit, prange

from fulldem.dem import diagnostics
from fulldem.dem import laws as contacts
from fulldem.dem import records
from fulldem.dem import stepper as dem_stepper
from fulldem.droplets import DropletStore


HERE = Path(__file__).resolve().parent

DIAMETER = 0.5e-3
DENSITY = 5100.0
SLAG_DENSITY = 3150.0
VISCOSITY = 0.45
GRAVITY = 9.81 * (DENSITY - SLAG_DENSITY) / DENSITY      # 3.7509 m/s^2, buoyancy folded in
STOKES_DRAG = 3.0 * math.pi * VISCOSITY * DIAMETER        # 2.1206e-3 N s/m
STIFFNESS = 5.0                                           # N/m
DAMPING_RATE = 2358.5                                     # gamma_n [1/s]: F_damping = m_eff gamma_n v_n
BOX = 0.2
STEP = 2e-5
SKIN = 0.25 * DIAMETER
STEPS = 2000


def run_dem(store, steps, dem_step, box_size, stiffness_ref, diameter_ref, restitution, wall_restitution, skin,
            body_acceleration, viscosity, report_steps=(), half_list=True, track_impulse=True):
    """DEM-only run in a closed box with all six walls and linear Stokes drag beta = 3 pi mu d in still fluid.

    Returns a dict: ``loop_seconds`` (the stepping loop only, set-up and first build excluded), ``rebuilds``
    (list builds during the loop), ``kinetic_energy`` {step: J} at ``report_steps``, ``max_overlap_ratio``,
    ``impulse`` (the drag impulses, (n, 3) [N s], if tracked) and the ``stepper``.
    """
    stepper = dem_stepper.DemStepper(store, (0.0, 0.0, 0.0), box_size, (False, False, False), dem_step, stiffness_ref,
                             diameter_ref, restitution, skin, body_acceleration, wall_restitution=wall_restitution,
                             half_list=half_list)
    stepper.droplets_changed()
    n = store.count
    stepper.set_drag(3.0 * math.pi * viscosity * store.diameter)
    still = np.zeros((1, 3))
    impulse = np.zeros((store.capacity, 3)) if track_impulse else dem_stepper.NO_IMPULSE
    builds_before = stepper.neighbours.builds
    energies = {}
    loop = 0.0
    report = sorted({int(s) for s in report_steps if 0 < int(s) <= steps})
    done = 0
    for target in report + [steps]:
        t0 = time.perf_counter()
        stepper.advance(target - done, still, impulse)
        loop += time.perf_counter() - t0
        done = max(done, target)
        if target in report:
            energies[target] = diagnostics.kinetic_energy(store.velocity, stepper.mass, n)
    return {"loop_seconds": loop, "rebuilds": stepper.neighbours.builds - builds_before,
            "kinetic_energy": energies, "max_overlap_ratio": stepper.max_overlap_ratio,
            "impulse": impulse[:n] if track_impulse else None, "stepper": stepper}


def damping_ratio_for_rate(rate, mass_effective, stiffness=STIFFNESS):
    """zeta of a contact whose dashpot is m_eff * rate: gamma = 2 zeta sqrt(k m_eff) -> zeta = rate/2 sqrt(m_eff/k)."""
    return 0.5 * rate * math.sqrt(mass_effective / stiffness)


# ------------------------------------------------------------------------------------------------ starting states
@njit(cache=True)
def _random_packing(n, side, diameter, seed, out):
    """Random sequential addition of n spheres in a cube of edge ``side`` (centres kept d/2 inside the faces)."""
    np.random.seed(seed)
    cell = diameter
    m = max(1, int(side / cell))
    cell = side / m
    heads = -np.ones(m * m * m, dtype=np.int64)
    nxt = -np.ones(n, dtype=np.int64)
    r = 0.5 * diameter
    placed = 0
    attempts = 0
    while placed < n:
        attempts += 1
        if attempts > 10000 * n:
            return placed
        x = r + np.random.random() * (side - diameter)
        y = r + np.random.random() * (side - diameter)
        z = r + np.random.random() * (side - diameter)
        cx, cy, cz = min(int(x / cell), m - 1), min(int(y / cell), m - 1), min(int(z / cell), m - 1)
        free = True
        for iz in range(max(cz - 1, 0), min(cz + 2, m)):
            for iy in range(max(cy - 1, 0), min(cy + 2, m)):
                for ix in range(max(cx - 1, 0), min(cx + 2, m)):
                    q = heads[ix + m * (iy + m * iz)]
                    while q >= 0 and free:
                        dx, dy, dz = out[q, 0] - x, out[q, 1] - y, out[q, 2] - z
                        if dx * dx + dy * dy + dz * dz < diameter * diameter:
                            free = False
                        q = nxt[q]
        if free:
            out[placed, 0], out[placed, 1], out[placed, 2] = x, y, z
            c = cx + m * (cy + m * cz)
            nxt[placed] = heads[c]
            heads[c] = placed
            placed += 1
    return placed


def sparse_state(n, seed=1):
    """Random non-overlapping packing at volume fraction 0.30 in a cube sub-box on the floor at the box centre."""
    side = (n * math.pi / 6.0 * DIAMETER**3 / 0.30) ** (1.0 / 3.0)
    pos = np.zeros((n, 3))
    placed = _random_packing(n, side, DIAMETER, seed, pos)
    if placed < n:
        raise RuntimeError(f"random packing placed only {placed} of {n} droplets")
    pos[:, 0] += 0.5 * (BOX - side)
    pos[:, 1] += 0.5 * (BOX - side)
    return _sorted(pos)


def dense_state(n):
    """Touching FCC bed (nearest neighbours exactly one diameter apart), bottom layer touching the floor."""
    a = DIAMETER * math.sqrt(2.0)                        # cubic lattice constant
    cells = int(math.ceil((n / 4.0) ** (1.0 / 3.0)))
    basis = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    idx = np.stack(np.meshgrid(*(np.arange(cells),) * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    pos = ((idx[:, None, :] + basis[None, :, :]).reshape(-1, 3)) * a
    pos = pos[np.lexsort((pos[:, 0], pos[:, 1], pos[:, 2]))][:n]       # fill from the bottom layer up
    extent = pos.max(axis=0)
    pos[:, 0] += 0.5 * (BOX - extent[0])
    pos[:, 1] += 0.5 * (BOX - extent[1])
    pos[:, 2] += 0.5 * DIAMETER
    return _sorted(pos)


def _sorted(pos):
    """Spatially sorted (cells of 2 d, x fastest), as both engines receive it."""
    key = np.floor(pos / (2 * DIAMETER)).astype(np.int64)
    order = np.lexsort((key[:, 0], key[:, 1], key[:, 2]))
    return np.ascontiguousarray(pos[order])


# ------------------------------------------------------------------------------------------------ our run
@njit(cache=True, parallel=True, fastmath=records.FASTMATH)
def _explicit_drag(velocity, drag, count, force):
    """Add -drag * v (half-step velocity) to the force, as LIGGGHTS's fix viscous does."""
    for p in prange(count):
        for a in range(3):
            force[p, a] -= drag * velocity[p, a]


def run_ours(pos, steps, drag="exact", half_list=True, track_impulse=False):
    """Our engine on the case; returns :func:`run_dem`'s dict."""
    n = len(pos)
    store = DropletStore(n)
    store.add(pos, DIAMETER, DENSITY)
    mass = DENSITY * math.pi / 6.0 * DIAMETER**3
    zeta_pair = damping_ratio_for_rate(DAMPING_RATE, 0.5 * mass)
    zeta_wall = damping_ratio_for_rate(DAMPING_RATE, mass)
    e_pair = contacts.restitution_coefficient(zeta_pair)
    e_wall = contacts.restitution_coefficient(zeta_wall)
    body = np.array([0.0, 0.0, -GRAVITY])
    report = [s for s in (200, 2000) if s <= steps]
    if drag == "exact":
        out = run_dem(store, steps, STEP, (BOX, BOX, BOX), STIFFNESS, DIAMETER, e_pair, e_wall, SKIN, body,
                          VISCOSITY, report_steps=report, half_list=half_list, track_impulse=track_impulse)
        return out
    # explicit drag, as in LIGGGHTS: beta = 0 in our integrator, -gamma v added to the force after the contacts
    stepper = ExplicitDragStepper(store, (0, 0, 0), (BOX, BOX, BOX), (False,) * 3, STEP, STIFFNESS, DIAMETER, e_pair,
                                  SKIN, body, wall_restitution=e_wall, half_list=half_list)
    stepper.droplets_changed()
    stepper.set_drag(np.zeros(n))
    still = np.zeros((1, 3))
    energies, loop, done = {}, 0.0, 0
    builds = stepper.neighbours.builds
    for target in report + [steps]:
        t0 = time.perf_counter()
        stepper.advance(target - done, still, dem_stepper.NO_IMPULSE)
        loop += time.perf_counter() - t0
        done = max(done, target)
        if target in report:
            energies[target] = diagnostics.kinetic_energy(store.velocity, stepper.mass, n)
    return {"loop_seconds": loop, "rebuilds": stepper.neighbours.builds - builds, "kinetic_energy": energies,
            "max_overlap_ratio": stepper.max_overlap_ratio, "stepper": stepper}


class ExplicitDragStepper(dem_stepper.DemStepper):
    """Our stepper with the drag as an explicit force -gamma v (LIGGGHTS's fix viscous) instead of the exact step."""

    def compute_forces(self):
        worst = super().compute_forces()
        _explicit_drag(self.store.velocity, STOKES_DRAG, self.store.count, self.force)
        return worst


# ------------------------------------------------------------------------------------------------ LIGGGHTS
LIGGGHTS_SCRIPT = """\
# DEM-only benchmark case, written by benchmarks/bench_dem.py (shared/reference/benchmark-case.md).
# Run: mpirun -np 2 liggghts -in in.bench_dem -var datafile FILE -var steps 2000
# The droplets rest on the floor at the box centre: the ranks split the box along x (through the packing's middle),
# not along z (the default for a cube), which would leave every droplet on one rank.
atom_style      sphere
atom_modify     map array
boundary        f f f
newton          off
communicate     single vel yes
units           si
processors      * 1 1
read_data       ${{datafile}}
neighbor        {skin!r} bin
neigh_modify    delay 0 every 1 check yes
fix             m1 all property/global kn peratomtypepair 1 {stiffness!r}
fix             m2 all property/global kt peratomtypepair 1 {stiffness!r}
fix             m3 all property/global gamman peratomtypepair 1 {damping_rate!r}
fix             m4 all property/global gammat peratomtypepair 1 0.0
fix             m5 all property/global coefficientFriction peratomtypepair 1 0.0
# frictionless Hooke: F = kn delta - m_eff gamman v_n (no tangential force: friction 0, gammat 0)
pair_style      gran model hooke/stiffness tangential no_history
pair_coeff      * *
timestep        {step!r}
fix             wx0 all wall/gran model hooke/stiffness tangential no_history primitive type 1 xplane 0.0
fix             wx1 all wall/gran model hooke/stiffness tangential no_history primitive type 1 xplane {box!r}
fix             wy0 all wall/gran model hooke/stiffness tangential no_history primitive type 1 yplane 0.0
fix             wy1 all wall/gran model hooke/stiffness tangential no_history primitive type 1 yplane {box!r}
fix             wz0 all wall/gran model hooke/stiffness tangential no_history primitive type 1 zplane 0.0
fix             wz1 all wall/gran model hooke/stiffness tangential no_history primitive type 1 zplane {box!r}
fix             gravity all gravity {gravity!r} vector 0.0 0.0 -1.0
fix             drag all viscous {drag!r}
fix             integrate all nve/sphere
compute         kinetic all ke
thermo_style    custom step atoms c_kinetic
thermo_modify   norm no lost error
thermo          200
run             ${{steps}}
"""


def liggghts_executable():
    """The LIGGGHTS binary on PATH (``liggghts`` or ``lmp_*``), or None."""
    found = shutil.which("liggghts")
    if found:
        return found
    for directory in os.environ.get("PATH", "").split(os.pathsep):
        try:
            names = sorted(os.listdir(directory))
        except OSError:
            continue
        for name in names:
            if name.startswith("lmp_") and os.access(os.path.join(directory, name), os.X_OK):
                return os.path.join(directory, name)
    return None


def write_liggghts_script(path=HERE / "liggghts" / "in.bench_dem"):
    """Write the input script (the same case, parameters from this file); returns its path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(LIGGGHTS_SCRIPT.format(skin=SKIN, stiffness=STIFFNESS, damping_rate=DAMPING_RATE, step=STEP,
                                           box=BOX, gravity=GRAVITY, drag=STOKES_DRAG))
    return path


def write_liggghts_data(pos, path):
    """A LIGGGHTS data file (atom_style sphere: id type diameter density x y z) with the same positions."""
    with open(path, "w") as out:
        out.write(f"LIGGGHTS data file: DEM benchmark, {len(pos)} droplets\n\n{len(pos)} atoms\n1 atom types\n\n")
        for axis in "xyz":
            out.write(f"0.0 {BOX!r} {axis}lo {axis}hi\n")
        out.write("\nAtoms\n\n")
        rows = np.column_stack([np.arange(1, len(pos) + 1), np.ones(len(pos)), np.full(len(pos), DIAMETER),
                                np.full(len(pos), DENSITY), pos])
        np.savetxt(out, rows, fmt=["%d", "%d", "%.17g", "%.17g", "%.17g", "%.17g", "%.17g"])


def run_liggghts(executable, pos, steps, ranks=2):
    """Run the case with LIGGGHTS under mpirun; returns loop seconds, kinetic energies, neighbour builds, RSS."""
    script = write_liggghts_script()
    with tempfile.TemporaryDirectory() as work:
        data = os.path.join(work, "droplets.data")
        write_liggghts_data(pos, data)
        command = ["mpirun", "--allow-run-as-root", "--oversubscribe", "-np", str(ranks), executable, "-in",
                   str(script), "-var", "datafile", data, "-var", "steps", str(steps), "-log", "none",
                   "-echo", "none", "-nocite"]
        result = subprocess.run(command, cwd=work, capture_output=True, text=True)
    text = result.stdout + result.stderr
    loop = re.search(r"Loop time of ([0-9.eE+-]+) on (\d+) procs for (\d+) steps", text)
    if result.returncode != 0 or loop is None:
        raise RuntimeError(f"LIGGGHTS failed (exit {result.returncode}):\n{text[-3000:]}")
    energies = {}
    for line in text.splitlines():
        fields = line.split()
        if len(fields) == 3 and fields[0].isdigit() and int(fields[0]) in (200, 2000):
            energies[int(fields[0])] = float(fields[2])
    builds = re.search(r"Neighbor list builds = (\d+)", text)
    rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    return {"loop_seconds": float(loop.group(1)), "kinetic_energy": energies,
            "rebuilds": int(builds.group(1)) if builds else -1, "peak_rss_mib": rss}


# ------------------------------------------------------------------------------------------------ main
def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, nargs="+", default=[10000, 130000], help="droplet counts")
    parser.add_argument("--steps", type=int, default=STEPS)
    parser.add_argument("--case", choices=["sparse", "dense"], nargs="+", default=["sparse", "dense"])
    parser.add_argument("--drag", choices=["exact", "explicit"], default="exact",
                        help="our drag: exact exponential step (default) or explicit like LIGGGHTS's fix viscous")
    parser.add_argument("--full-list", dest="half_list", action="store_false",
                        help="full neighbour list (each pair from both sides, one pass per step) instead of half")
    parser.add_argument("--impulse", action="store_true",
                        help="also accumulate the drag impulse the fluid would receive (not needed DEM-only)")
    found = liggghts_executable()
    parser.add_argument("--liggghts", dest="liggghts", action="store_true", default=found is not None,
                        help=f"also run LIGGGHTS with 2 MPI ranks (default: on if found; found: {found})")
    parser.add_argument("--no-liggghts", dest="liggghts", action="store_false")
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=1,
                        help="runs per engine, interleaved; the fastest of each is reported")
    args = parser.parse_args(argv)

    print(f"DEM-only benchmark: {args.steps} steps of {STEP} s, k_n = {STIFFNESS} N/m, gamma_n = {DAMPING_RATE} 1/s, "
          f"skin {SKIN * 1e3:.3f} mm; ours: Numba {numba.__version__}, {numba.get_num_threads()} threads "
          f"(threading layer: {numba.config.THREADING_LAYER_PRIORITY[0]} first), drag {args.drag}, "
          f"{'half' if args.half_list else 'full'} list, drag impulse {'tracked' if args.impulse else 'not tracked'}")
    print(f"load average at start: {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs (shared machine: compare the "
          "ratio within this run, not absolute figures across runs)")
    if args.liggghts and found is None:
        print("LIGGGHTS: not found on PATH (liggghts or lmp_*): skipped. Debian: apt-get install liggghts")
        args.liggghts = False
    run_ours(sparse_state(64) if "sparse" in args.case else dense_state(64), 3, args.drag, args.half_list)  # compile
    rows = []
    for case in args.case:
        for n in args.n:
            pos = sparse_state(n) if case == "sparse" else dense_state(n)
            best, lbest = None, None
            for _ in range(args.repeat):  # interleaved, so both engines see the same load on the shared machine
                out = run_ours(pos, args.steps, args.drag, args.half_list, track_impulse=args.impulse)
                if best is None or out["loop_seconds"] < best["loop_seconds"]:
                    best = out
                if args.liggghts:
                    lout = run_liggghts(found, pos, args.steps, args.ranks)
                    if lbest is None or lout["loop_seconds"] < lbest["loop_seconds"]:
                        lbest = lout
            ours = n * args.steps / best["loop_seconds"]
            ke = best["kinetic_energy"]
            print(f"{case:6s} n={n:7d}  ours {ours:9.3e} particle-steps/s  rebuilds {best['rebuilds']}  "
                  f"KE(200) {ke.get(200, math.nan):.9e} J  KE(2000) {ke.get(2000, math.nan):.9e} J  "
                  f"max overlap {best['max_overlap_ratio']:.2e} d  peak RSS "
                  f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0:.0f} MiB", flush=True)
            if args.liggghts:
                theirs = n * args.steps / lbest["loop_seconds"]
                lke = lbest["kinetic_energy"]
                print(f"{'':6s} {'':9s}  LIGGGHTS {args.ranks} ranks {theirs:9.3e} particle-steps/s  rebuilds "
                      f"{lbest['rebuilds']}  KE(200) {lke.get(200, math.nan):.9e} J  KE(2000) "
                      f"{lke.get(2000, math.nan):.9e} J  peak RSS/rank {lbest['peak_rss_mib']:.0f} MiB")
                same = run_ours(pos, args.steps, "explicit", args.half_list)["kinetic_energy"] \
                    if args.drag == "exact" else ke
                agreement = "  ".join(
                    f"KE({s}) ours/LIGGGHTS - 1: exact drag {ke.get(s, math.nan) / lke.get(s, math.nan) - 1:+.2e}, "
                    f"explicit drag {same.get(s, math.nan) / lke.get(s, math.nan) - 1:+.2e}" for s in (200, 2000))
                print(f"{'':6s} {'':9s}  ratio ours/LIGGGHTS = {ours / theirs:.2f}   {agreement}", flush=True)
                rows.append((case, n, ours, theirs))
    print(f"load average at end: {os.getloadavg()[0]:.2f}")
    if rows:
        print("\nsummary (particle-steps per second)\ncase    n        ours        LIGGGHTS    ratio")
        for case, n, ours, theirs in rows:
            print(f"{case:6s} {n:7d}  {ours:10.3e}  {theirs:10.3e}  {ours / theirs:5.2f}")


if __name__ == "__main__":
    sys.exit(main())
