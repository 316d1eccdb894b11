"""Run every collective-settling verification case of the coupled engine and write the measured figures.

    python reports/fulldem_verification.py            # all cases (about 20-30 minutes on 2 cores)
    python reports/fulldem_verification.py --quick    # the two default-tier test cases only (under a minute)

Writes reports/fulldem_verification.md (atomically, at the end) with one table row per case: what was run, the
measured speed, the reference and their ratio. The set-ups are those of tests/test_fulldem_verification.py
(fulldem/verification.py), so the numbers quoted in the tests' docstrings come from here.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from fulldem.verification import check_cloud, check_hindered, check_homogeneous
from settler.cases import load_case
from settler.output import atomic_write_text
from settler.physics import richardson_zaki_factor

ROOT = Path(__file__).resolve().parents[1]
#: Heading of the hand-written part of the report, kept when the table is rewritten.
DISCUSSION = "## Discussion"


def hindered_row(phi, t_end, label, **setup):
    clock = time.time()
    ratio, record, sim, droplet_re = check_hindered(phi, t_end, **setup)
    u_stokes = sim.terminal_velocity(float(sim.store.diameter[0]))
    u_rz = u_stokes * richardson_zaki_factor(phi)
    return (f"hindered, front | {label}, phi = {phi}, {record.count} droplets, t = 1-{t_end:g} s | "
            f"{ratio * u_rz * 1e3:.3f} mm/s | U_RZ = {u_rz * 1e3:.3f} mm/s | **{ratio:.3f}** | "
            f"{time.time() - clock:.0f} s"), ratio


def homogeneous_row(phi):
    clock = time.time()
    sim, u_rz, speeds = check_homogeneous(phi)
    ratio = float(np.mean(speeds)) / u_rz
    return (f"hindered, homogeneous | periodic 48 mm cube, phi = {phi}, {sim.store.count} droplets, t = 0.5-1.5 s | "
            f"{np.mean(speeds) * 1e3:.3f} mm/s | U_RZ = {u_rz * 1e3:.3f} mm/s | **{ratio:.3f}** | "
            f"{time.time() - clock:.0f} s"), ratio


def cloud_row(n_a_over_r, label, **setup):
    clock = time.time()
    cloud, speed, fallen, spread = check_cloud(n_a_over_r, **setup)
    reference = cloud.reference()
    return (f"falling cloud | {label}, N = {cloud.count}, N a/R = {cloud.n_a_over_r:.2f}, cloud Re = "
            f"{cloud.reynolds(speed):.2f}, fallen {fallen:.1f} R | {speed / cloud.stokes:.3f} U_St | "
            f"{reference / cloud.stokes:.3f} U_St (unbounded {cloud.nitsche_batchelor() / cloud.stokes:.3f}) | "
            f"**{speed / reference:.3f}** | {time.time() - clock:.0f} s"), speed / reference


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="only the two default-tier test cases")
    parser.add_argument("--only", type=int, default=None, help="run only case number ONLY (0-based) and print its row")
    parser.add_argument("--out", type=Path, default=ROOT / "reports" / "fulldem_verification.md")
    args = parser.parse_args(argv)
    small = "36 x 36 x 72 mm"
    large = dict(width=0.048, height=0.144, fill=0.132)
    cases = [(hindered_row, (0.1, 4.0, small), {}), (cloud_row, (4.0, "R = 4 cells, box 8 R"), {})]
    if not args.quick:
        cases += [(hindered_row, (phi, 4.0, small), {}) for phi in (0.05, 0.2)]
        cases += [(hindered_row, (phi, 5.0, "48 x 48 x 144 mm"), large) for phi in (0.05, 0.1, 0.2)]
        cases += [(homogeneous_row, (phi,), {}) for phi in (0.05, 0.1, 0.2)]
        cases += [(cloud_row, (nar, "R = 4 cells, box 8 R"), {}) for nar in (2.0, 5.0, 10.0)]
        cases += [(cloud_row, (4.0, "R = 6 cells, box 8 R"), dict(cells_per_radius=6, cell=20e-3 / 6,
                                                                 diameter=1e-3)),
                  (cloud_row, (4.0, "R = 4 cells, box 12 R"), dict(box_radii=12))]
    if args.only is not None:  # one case, in this process (the others run each in a fresh process)
        function, positional, keywords = cases[args.only]
        print(function(*positional, **keywords)[0], flush=True)
        return
    rows = []
    for index in range(len(cases)):
        result = subprocess.run([sys.executable, __file__, "--only", str(index)] + (["--quick"] if args.quick else []),
                                capture_output=True, text=True)
        if result.returncode != 0:
            raise RuntimeError(f"case {index} failed:\n{result.stderr[-3000:]}")
        row = result.stdout.strip().splitlines()[-1]
        print(row, flush=True)
        rows.append(row)
    # the hand-written discussion after DISCUSSION in an existing report is kept (re-read it against the new table)
    previous = args.out.read_text() if args.out.exists() else ""
    discussion = previous[previous.index(DISCUSSION):] if DISCUSSION in previous else ""
    text = ("# fulldem: collective-settling verification, measured\n\n"
            f"Written by `python {Path(__file__).relative_to(ROOT)}{' --quick' if args.quick else ''}` on "
            f"{time.strftime('%Y-%m-%d')}, {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
            f"load average at the end {os.getloadavg()[0]:.1f}; coupling kernel "
            f"`{load_case('simple').fulldem.kernel}` (the default). Set-ups: `fulldem/verification.py`; tests: "
            "`tests/test_fulldem_verification.py` (tolerances: 15 % hindered settling, 25 % falling cloud).\n\n"
            "| check | case | measured | reference | ratio | wall |\n|---|---|---|---|---|---|\n"
            + "\n".join(f"| {row} |" for row in rows) + "\n" + ("\n" + discussion if discussion else ""))
    atomic_write_text(args.out, text)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
