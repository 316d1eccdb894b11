"""Collective settling in the coupled engine against independent references (physics.md section 4).

* Hindered settling: the top interface of an initially uniform random suspension of monodisperse point-like
  droplets descends at the Richardson-Zaki velocity U_St (1 - phi)^4.65 (Richardson & Zaki 1954), U_St the
  single-droplet Schiller-Naumann terminal velocity; tolerance 15 %.
* Falling cloud: a spherical cloud of N droplets of radius a in a ball of radius R falls at
  U_St (1 + 1.2 N a / R) (Nitsche & Batchelor, JFM 340 (1997)) in unbounded Stokes flow. Here the box is periodic,
  and its images slow the cloud at first order by Hasimoto's (1959) lattice term -2.837 N a U_St / L (the cloud's
  far field is the Stokeslet of its total weight N 6 pi mu a U_St); at L = 8 R that is 30 % of the collective part,
  so the reference is U_St (1 + 1.2 N a/R - 2.837 N a/L); tolerance 25 %, cloud Reynolds number below 1.

Default tier: phi = 0.1 and N a/R = 4 (about a minute together on 2 cores). Slow tier (``-m slow``): phi = 0.05, 0.2
in a larger box, N a/R = 2 ... 10, and a finer grid and a larger box for the cloud. The numbers, the commands and the
discussion (why the front runs a few % ahead of the bulk; why the cloud falls 12 % below the reference at R = 4
cells: the smoothing kernel) are in reports/fulldem_verification.md. The set-up functions are shared with
the verification report (reports/verification.py, through analysis/verification.py), which also draws the cloud
turning into a torus.
"""

from __future__ import annotations

import numpy as np
import pytest

from fulldem.cases.cloud import check_cloud
from fulldem.cases.suspensions import check_hindered, check_homogeneous


# ---------------------------------------------------------------------------------------------------- hindered settling
def test_hindered_settling_front_richardson_zaki():
    """phi = 0.1, 2 mm droplets, 6 mm cells (3 diameters, sigma = 1 cell), 36 x 36 x 72 mm periodic in x, y (2042
    droplets): the height with 5 % of the droplets above it descends, from t = 1 s to 4 s, at U_St (1 - phi)^4.65
    within 15 % (measured 1.04; 1.03 with the direct kernel)."""
    ratio, record, sim, droplet_re = check_hindered(0.1, 4.0)
    assert droplet_re < 0.2
    assert ratio == pytest.approx(1.0, rel=0.15)


@pytest.mark.slow
@pytest.mark.parametrize("phi", [0.05, 0.2])
def test_hindered_settling_front_other_fractions(phi):
    """phi = 0.05 and 0.2 in the same box: the front descends at the Richardson-Zaki velocity within 15 %
    (measured 0.96 and 1.11)."""
    ratio, record, sim, _ = check_hindered(phi, 4.0)
    assert ratio == pytest.approx(1.0, rel=0.15)


@pytest.mark.slow
@pytest.mark.parametrize("phi", [0.05, 0.1, pytest.param(0.2, marks=pytest.mark.xfail(
    strict=True, reason="known discrepancy: box-scale convection in the tall column; front 1.26 U_RZ, bulk "
                        "1.02-1.05 U_RZ (reports/fulldem_verification.md)"))])
def test_hindered_settling_front_large_box(phi):
    """phi = 0.05, 0.1, 0.2 in a 48 x 48 x 144 mm box (8 x 8 x 24 cells; 3 630 - 14 521 droplets), 5 s: the front
    descends at the Richardson-Zaki velocity within 15 %. Measured 1.00, 1.10 and 1.26. At phi = 0.2 the bulk
    settles at 1.02-1.05 U_RZ (0.88 in the 72 mm column) and the front runs ~23 % ahead of it; both point to
    box-scale convection, which grows in the taller, wider column (fluid velocity fluctuations ~4 U_RZ). phi = 0.2
    fails the 15 % tolerance with seeds 1-3, with half the fluid step, without fluid inertia, with a front defined
    from the concentration, and with 4 mm cells (concentration front): reported, not hidden, as a strict xfail
    (reports/fulldem_verification.md)."""
    ratio, record, sim, _ = check_hindered(phi, 5.0, width=0.048, height=0.144, fill=0.132)
    assert ratio == pytest.approx(1.0, rel=0.15)


@pytest.mark.slow
@pytest.mark.parametrize("phi", [0.05, 0.1, 0.2])
def test_homogeneous_suspension_richardson_zaki(phi):
    """Without a front or walls: a random suspension in a periodic 48 mm cube settles, in the frame of zero volume
    flux, at the Richardson-Zaki velocity within 15 % (measured 0.93, 0.91, 0.87 of it, steady from t = 0.5 s).
    Below it because the resolved flow counts again what the Di Felice closure already contains: the hard-sphere
    correlation hole (structure factor S(k) < 1 at the kernel's scales) slows each droplet's neighbourhood by
    3.5, 6.7, 13 % of U_RZ for sigma = 3 d (Percus-Yevick estimate; halved at sigma = 6 d, measured 0.94 at phi =
    0.2 with fulldem.sigma_cells = 2)."""
    sim, u_rz, speeds = check_homogeneous(phi)
    assert np.mean(speeds) / u_rz == pytest.approx(1.0, rel=0.15)
    assert np.std(speeds) < 0.02 * u_rz  # steady


# ---------------------------------------------------------------------------------------------------- falling cloud
def test_falling_cloud_nitsche_batchelor():
    """N a/R = 4 (107 droplets of 1.5 mm, R = 4 cells = 20 mm) in a periodic 8 R cube at cloud Re 0.2: the centroid
    velocity from 5 to 8 R^2/nu equals U_St (1 + 1.2 N a/R - 2.837 N a/L) within 25 % (measured 0.89; the Gaussian
    kernel of width sigma = R/4 alone lowers the collective part by 11 %). The cloud has fallen about one radius and
    is still a ball (radius of gyration within 3 % of its initial value)."""
    cloud, speed, fallen, spread = check_cloud(4.0)
    assert cloud.reynolds(speed) < 1.0
    assert cloud.sim.density * cloud.stokes * cloud.diameter / cloud.sim.viscosity < 1e-2
    assert abs(spread - 1.0) < 0.03 and 0.3 < fallen < 2.0
    assert speed == pytest.approx(cloud.reference(), rel=0.25)
    assert speed > 3.0 * cloud.stokes  # collective settling: several times faster than one droplet


@pytest.mark.slow
@pytest.mark.parametrize("n_a_over_r", [2.0, 5.0, 10.0])
def test_falling_cloud_sweep(n_a_over_r):
    """N a/R = 2, 5, 10 at cloud Re 0.3: the centroid velocity equals the box-corrected Nitsche-Batchelor velocity
    within 25 %."""
    cloud, speed, fallen, spread = check_cloud(n_a_over_r)
    assert cloud.reynolds(speed) < 1.0
    assert speed == pytest.approx(cloud.reference(), rel=0.25)


@pytest.mark.slow
@pytest.mark.parametrize("setup", [dict(cells_per_radius=6, cell=20e-3 / 6, diameter=1e-3), dict(box_radii=12)],
                         ids=["R_6_cells", "box_12R"])
def test_falling_cloud_resolution_and_box(setup):
    """The same at R = 6 cells (kernel smoothing 6 % instead of 11 %) and in a 12 R box (image term 20 % of the
    collective part instead of 30 %): within 25 % of the box-corrected reference (measured 0.96 and 0.87)."""
    cloud, speed, fallen, spread = check_cloud(4.0, **setup)
    assert cloud.reynolds(speed) < 1.0
    assert speed == pytest.approx(cloud.reference(), rel=0.25)
