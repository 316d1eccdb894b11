"""Coupling kernels: conservation of what is deposited, adjointness of interpolation and deposition, the telescoping
pressure-gradient sum behind momentum conservation, and the self-induced velocity correction."""

import math

import numpy as np
import pytest

from fulldem.coupling import filtered, mobility, smoothing
from fulldem.fluid.grid import Grid


CUT = smoothing.DEFAULT_CUT


def _droplets(rng, n, grid, dmin=0.3e-3, dmax=12e-3):
    lo, hi = np.asarray(grid.lower), grid.upper
    pos = lo + rng.uniform(0.02, 0.98, size=(n, 3)) * (hi - lo)
    diam = rng.uniform(dmin, dmax, size=n)
    return pos, diam


def _args(grid):
    return grid.spacing, np.asarray(grid.lower, float), np.asarray(grid.shape), np.asarray(grid.periodic)


def _field(grid, component):
    return grid.zeros_cells() if component == 3 else np.zeros(grid.face_shape(component))


@pytest.mark.parametrize("periodic", [(False, False, False), (True, True, True), (True, False, True)])
@pytest.mark.parametrize("component", [0, 1, 2, 3])
def test_deposit_conserves_and_is_adjoint_of_interpolate(periodic, component):
    grid = Grid((12, 10, 14), 0.004, (0.1, -0.02, 0.0), periodic)
    rng = np.random.default_rng(component)
    pos, diam = _droplets(rng, 60, grid)
    value = rng.uniform(0.5, 2.0, 60)
    out = _field(grid, component)
    scratch = np.zeros((smoothing.thread_count(), *out.shape))
    smoothing.deposit(pos, diam, value, 60, component, out, *_args(grid), 1.0, 0.5, CUT, scratch)
    assert out.sum() == pytest.approx(value.sum(), rel=1e-13)  # nothing lost, nothing created
    if component < 3 and not periodic[component]:
        # wall-normal boundary faces carry imposed velocities: they receive nothing
        assert np.all(np.take(out, [0, -1], axis=component) == 0.0)
    # adjoint: <deposit(value), field> = <value, interpolate(field)>
    field = rng.normal(size=out.shape)
    interp = np.zeros(60)
    smoothing.interpolate(pos, diam, 60, component, field, interp, *_args(grid), 1.0, 0.5, CUT)
    assert np.sum(out * field) == pytest.approx(np.sum(value * interp), rel=1e-12)


def test_interpolation_reproduces_constant_and_linear_fields():
    grid = Grid((16, 16, 16), 0.005, (0, 0, 0), (True, True, True))
    rng = np.random.default_rng(3)
    pos, diam = _droplets(rng, 40, grid, dmax=4e-3)
    field = np.full(grid.face_shape(0), 2.5)
    out = np.zeros(40)
    smoothing.interpolate(pos, diam, 40, 0, field, out, *_args(grid), 1.0, 0.5, CUT)
    np.testing.assert_allclose(out, 2.5, rtol=1e-14)
    # a field linear in z on x-faces: the truncated, discretely normalised Gaussian has a first moment that is not
    # exactly zero, so the interpolated position is off by a small fraction of a cell (bounded here by 0.1 h)
    z = grid.cell_centres(2)
    field = np.broadcast_to(3.0 * z, grid.face_shape(0)).copy()
    inner = (pos[:, 2] > 0.02) & (pos[:, 2] < 0.06)
    smoothing.interpolate(pos, diam, 40, 0, field, out, *_args(grid), 1.0, 0.5, CUT)
    offset = np.abs(out[inner] / 3.0 - pos[inner, 2])
    assert offset.max() < 0.1 * grid.spacing


def test_pressure_gradient_force_telescopes_to_zero():
    """sum over faces of eps (grad p) V + sum over droplets of V_p (grad p)_interp = sum over faces of grad p V = 0
    in a periodic box: the momentum balance of the coupling needs nothing else from the pressure."""
    grid = Grid((10, 12, 8), 0.005, (0, 0, 0), (True, True, True))
    rng = np.random.default_rng(5)
    n = 80
    pos, diam = _droplets(rng, n, grid, dmax=6e-3)
    volume = np.pi / 6 * diam**3
    p = rng.normal(size=grid.shape)
    grads = grid.zeros_faces()
    smoothing.pressure_gradient_faces(p, grid.spacing, np.asarray(grid.periodic), *grads)
    total = np.zeros(3)
    for a in range(3):
        phi = np.zeros(grid.face_shape(a))
        scratch = np.zeros((smoothing.thread_count(), *phi.shape))
        smoothing.deposit(pos, diam, volume / grid.cell_volume, n, a, phi, *_args(grid), 1.0, 0.5, CUT, scratch)
        eps = 1.0 - phi
        g_at = np.zeros(n)
        smoothing.interpolate(pos, diam, n, a, grads[a], g_at, *_args(grid), 1.0, 0.5, CUT)
        fluid = np.sum(eps[tuple(slice(0, s) for s in grid.shape)] * grads[a][tuple(slice(0, s) for s in grid.shape)])
        total[a] = fluid * grid.cell_volume + np.sum(volume * g_at)
        scale = np.sum(np.abs(grads[a])) * grid.cell_volume
        assert abs(total[a]) < 1e-12 * scale


def test_self_weight_matches_own_deposit_seen_back():
    grid = Grid((12, 12, 12), 0.004, (0, 0, 0), (False, False, False))
    rng = np.random.default_rng(9)
    pos, diam = _droplets(rng, 5, grid)
    for p in range(5):
        out = grid.zeros_cells()
        smoothing.deposit(pos[p:p + 1], diam[p:p + 1], np.ones(1), 1, 3, out, *_args(grid), 1.0, 0.5, CUT,
                   np.zeros((1, *out.shape)))
        seen = np.zeros(1)
        smoothing.interpolate(pos[p:p + 1], diam[p:p + 1], 1, 3, out, seen, *_args(grid), 1.0, 0.5, CUT)
        sw = np.zeros(1)
        smoothing.self_weight(pos[p:p + 1], diam[p:p + 1], 1, 3, sw, *_args(grid), 1.0, 0.5, CUT)
        assert sw[0] == pytest.approx(seen[0], rel=1e-12)


def test_gaussian_self_mobility_reproduces_stokes_drag():
    # Maxey & Patel (2001): a Gaussian of width a/sqrt(pi) has the self-mobility of a sphere of radius a
    a, mu = 1e-3, 0.45
    assert mobility.gaussian_self_mobility(a / math.sqrt(math.pi), mu) == pytest.approx(1 / (6 * math.pi * mu * a),
                                                                                 rel=1e-14)


@pytest.mark.parametrize("ratio", [1.0, 2.0])
def test_discrete_mobility_close_to_continuous(ratio):
    """On a resolved kernel (sigma >= h) the grid's second-order operators reproduce the continuous Gaussian
    self-mobility to within the O(h^2/sigma^2) truncation error; at sigma = 2h within 5 %."""
    factor = mobility.discrete_mobility_factor(ratio)
    assert abs(factor - 1.0) < (0.10 if ratio == 1.0 else 0.05)


def test_oseen_factor_limits():
    # Re -> 0: Stokes; small Re: the Oseen correction is linear in Re; large Re: the disturbance is swept away
    assert mobility.oseen_factor(0.0) == pytest.approx(1.0, abs=1e-3)
    f = mobility.oseen_factor(np.array([0.01, 0.02]))
    assert (1 - f[1]) / (1 - f[0]) == pytest.approx(2.0, rel=0.05)
    big = mobility.oseen_factor(np.array([1e3, 2e3]))
    assert big[0] / big[1] == pytest.approx(2.0, rel=0.05)
    assert np.all(np.diff(mobility.oseen_factor(np.logspace(-2, 3, 20))) < 0)


@pytest.mark.parametrize("periodic", [(False, False, False), (True, False, True)])
def test_fused_passes_match_single_quantity_kernels(periodic):
    """deposit_many / interpolate_many (one stencil per droplet for several quantities, stored in a table by one
    pass and loaded by the next) give exactly what the single-quantity kernels give, and the self weight of the
    cells comes out of the same pass."""
    grid = Grid((12, 10, 14), 0.004, (0.1, -0.02, 0.0), periodic)
    rng = np.random.default_rng(11)
    n = 70
    pos, diam = _droplets(rng, n, grid)
    components = np.array([0, 1, 2, 3, 0, 2], dtype=np.int64)
    values = rng.uniform(-1.0, 2.0, size=(len(components), n))
    outs = [_field(grid, c) for c in components]
    nx, ny, nz = grid.shape
    scratch = np.zeros((smoothing.thread_count(), len(components), nx + 1, ny + 1, nz + 1))
    # the first pass stores the stencils (one droplet too wide for the table: recomputed), the second loads them
    diam[7] = 0.05
    table = smoothing.stencil_table(n)
    smoothing.deposit_many(pos, diam, values, n, components, tuple(outs), *_args(grid), 1.0, 0.5, CUT, scratch, *table,
                    smoothing.STORE)
    assert table[1][7, 0, 0] == 0 and (table[1][:, 0, 0] > 0).sum() > n // 2
    fields = [rng.normal(size=o.shape) for o in outs]
    seen = np.zeros((len(components), n))
    own = np.zeros(n)
    smoothing.interpolate_many(pos, diam, n, components, tuple(fields), seen, own, *_args(grid), 1.0, 0.5, CUT, *table,
                        smoothing.LOAD)
    for k, c in enumerate(components):
        single = _field(grid, c)
        smoothing.deposit(pos, diam, values[k], n, c, single, *_args(grid), 1.0, 0.5, CUT,
                   np.zeros((smoothing.thread_count(), *single.shape)))
        np.testing.assert_array_equal(outs[k], single)
        interp = np.zeros(n)
        smoothing.interpolate(pos, diam, n, c, fields[k], interp, *_args(grid), 1.0, 0.5, CUT)
        np.testing.assert_array_equal(seen[k], interp)
    sw = np.zeros(n)
    smoothing.self_weight(pos, diam, n, 3, sw, *_args(grid), 1.0, 0.5, CUT)
    np.testing.assert_array_equal(own, sw)


def test_weights_match_direct_gaussian():
    """The recurrence that evaluates the Gaussian at consecutive nodes agrees with one exp per node to round-off."""
    idx = np.zeros(smoothing.MAX_STENCIL, dtype=np.int64)
    wts = np.zeros(smoothing.MAX_STENCIL)
    for sigma, x in [(0.004, 0.0513), (0.011, 0.0377), (0.0021, 0.0099), (0.05, 0.1)]:
        count = smoothing.weights_1d(x, 0.0, 0.004, 40, True, True, False, sigma, CUT, idx, wts)
        r = idx[:count] - x / 0.004
        direct = np.exp(-r**2 / (2 * (sigma / 0.004) ** 2))
        np.testing.assert_allclose(wts[:count], direct / direct.sum(), rtol=1e-13)
        assert wts[:count].sum() == pytest.approx(1.0, rel=1e-15)


# ------------------------------------------------------------------------------------------ filtered kernel
def _filtered_deposit(kernel, grid, pos, values, component):
    """The stepper's two-step deposit: :func:`smoothing.cic_deposit_many`, then the filter."""
    n = len(pos)
    raw = _field(grid, component)
    smoothing.cic_deposit_many(pos, values.reshape(1, -1), n, np.array([component]), (raw,), *_args(grid),
                        np.zeros((2, 1, *[s + 1 for s in grid.shape])))
    return kernel.filter(raw, component)


def _filtered_interpolate(kernel, grid, pos, field, component):
    n = len(pos)
    out = np.zeros((1, n))
    smoothing.cic_interpolate_many(pos, n, np.array([component]), (kernel.filter(field, component),), out, *_args(grid))
    return out[0]


def _linear_weights(x, lower, h, n_cells, staggered, wall_normal, periodic):
    """NumPy-free twin of the trilinear weights along one axis: the two nodes around x, each clamped into the valid
    nodes of a walled axis (so weight beyond the last node goes to it), wrapped on a periodic one."""
    s = (x - lower) / h - (0.0 if staggered else 0.5)
    first = math.floor(s)
    nodes = [(first, 1.0 - (s - first)), (first + 1, s - first)]
    if periodic:
        return [(k % n_cells, w) for k, w in nodes]
    low, high = (1, n_cells - 1) if (staggered and wall_normal) else (0, n_cells if staggered else n_cells - 1)
    return [(min(max(k, low), high), w) for k, w in nodes]


@pytest.mark.parametrize("periodic", [(False, False, False), (True, True, True), (True, False, True)])
def test_trilinear_kernels_match_a_direct_twin(periodic):
    """The trilinear deposit and interpolation (the filtered kernel's first step) against a plain-Python twin built
    from the weights' definition, for all four arrays in one fused pass, droplets anywhere in the box including the
    half cells next to the walls; to round-off."""
    grid = Grid((9, 11, 8), 0.004, (0.1, -0.02, 0.0), periodic)
    rng = np.random.default_rng(7)
    n = 300
    lo, hi = np.asarray(grid.lower), grid.upper
    pos = lo + rng.uniform(0.0, 1.0, size=(n, 3)) * (hi - lo)
    components = np.array([0, 1, 2, 3, 2], dtype=np.int64)
    values = rng.uniform(-1.0, 2.0, size=(5, n))
    twin = tuple(_field(grid, c) for c in components)
    fields = tuple(rng.normal(size=f.shape) for f in twin)
    seen = np.zeros((5, n))
    for p in range(n):
        for k, c in enumerate(components):
            axes = [_linear_weights(pos[p, a], lo[a], grid.spacing, grid.shape[a], c == a, True, periodic[a])
                    for a in range(3)]
            for i, wi in axes[0]:
                for j, wj in axes[1]:
                    for m, wm in axes[2]:
                        twin[k][i, j, m] += values[k, p] * wi * wj * wm
                        seen[k, p] += wi * wj * wm * fields[k][i, j, m]
    kernel = tuple(_field(grid, c) for c in components)
    smoothing.cic_deposit_many(pos, values, n, components, kernel, *_args(grid),
                        np.zeros((2, 5, *[s + 1 for s in grid.shape])))
    for a, b in zip(twin, kernel):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-13 * np.abs(a).max())
    out = np.zeros((5, n))
    smoothing.cic_interpolate_many(pos, n, components, fields, out, *_args(grid))
    np.testing.assert_allclose(out, seen, rtol=0, atol=1e-13)


@pytest.mark.parametrize("periodic", [(False, False, False), (True, True, True), (True, False, True)])
@pytest.mark.parametrize("component", [0, 1, 2, 3])
def test_filtered_kernel_conserves_and_is_adjoint(periodic, component):
    """Two-step kernel (trilinear weights, then the grid filter G): the deposit's sum equals the deposited total,
    wall-normal boundary faces receive nothing, and <D v, f> = <v, I f> (I = D^T), to round-off, with droplets
    anywhere in the box including the half cells next to the walls."""
    grid = Grid((12, 10, 14), 0.004, (0.1, -0.02, 0.0), periodic)
    kernel = filtered.FilteredKernel(grid.shape, periodic, 1.0)
    rng = np.random.default_rng(10 + component)
    lo, hi = np.asarray(grid.lower), grid.upper
    pos = lo + rng.uniform(0.0, 1.0, size=(80, 3)) * (hi - lo)
    values = rng.uniform(0.5, 2.0, 80)
    out = _filtered_deposit(kernel, grid, pos, values, component)
    valid = out if component == 3 or periodic[component] else (out[1:-1] if component == 0 else (
        out[:, 1:-1] if component == 1 else out[:, :, 1:-1]))
    if component < 3 and periodic[component]:  # the last face is the first again, and receives nothing itself
        valid = np.take(out, range(grid.shape[component]), axis=component)
    assert valid.sum() == pytest.approx(values.sum(), rel=1e-13)
    assert out.sum() == pytest.approx(values.sum(), rel=1e-13)
    field = rng.normal(size=out.shape)
    seen = _filtered_interpolate(kernel, grid, pos, field, component)
    assert np.sum(out * field) == pytest.approx(np.sum(values * seen), rel=1e-12)


def _wall_face_deposit(kernel, grid, pos, values, component):
    """The two-step deposit with ``wall_faces`` (fulldem.near_wall = "wall")."""
    n = len(pos)
    raw = _field(grid, component)
    smoothing.cic_deposit_many(pos, values.reshape(1, -1), n, np.array([component]), (raw,), *_args(grid),
                               np.zeros((2, 1, *[s + 1 for s in grid.shape])), True)
    return kernel.filter(raw, component)


def _wall_face_interpolate(kernel, grid, pos, field, component):
    n = len(pos)
    out = np.zeros((1, n))
    smoothing.cic_interpolate_many(pos, n, np.array([component]), (kernel.filter(field, component),), out,
                                   *_args(grid), True)
    return out[0]


def test_wall_faces_let_the_wall_normal_velocity_fall_to_zero_at_the_wall():
    """fulldem.near_wall = "wall": a uniform downflow W on every interior face of the wall-normal component (zero
    on the boundary faces, as the no-penetration condition holds it) is seen by a droplet at height z within the
    first cell as W z / h, linear interpolation to the wall's zero (to round-off); with the interior weights (the
    reference set's engine) it sees W down to the wall. The tangential components are untouched."""
    grid = Grid((6, 5, 8), 0.005, (0.0, 0.0, 0.0), (False, False, False))
    kernel = filtered.FilteredKernel(grid.shape, grid.periodic, 1.0)
    h = grid.spacing
    z = np.array([0.05, 0.3, 0.6, 0.95, 1.0, 1.7, 4.0]) * h
    pos = np.column_stack([np.full(z.size, 2.3 * h), np.full(z.size, 2.6 * h), z])
    w = _field(grid, 2)
    w[:, :, 1:-1] = -0.02  # m/s, uniform on the interior faces: the filter keeps it uniform there
    seen = _wall_face_interpolate(kernel, grid, pos, w, 2)
    np.testing.assert_allclose(seen, -0.02 * np.minimum(z / h, 1.0), rtol=0, atol=1e-15)
    np.testing.assert_allclose(_filtered_interpolate(kernel, grid, pos, w, 2), -0.02, rtol=0, atol=1e-15)
    top = pos.copy()
    top[:, 2] = grid.upper[2] - z  # the lid too
    np.testing.assert_allclose(_wall_face_interpolate(kernel, grid, top, w, 2), -0.02 * np.minimum(z / h, 1.0),
                               rtol=0, atol=1e-15)
    u = _field(grid, 0)
    u[1:-1] = 0.01  # tangential to the floor: not a wall-normal component there
    np.testing.assert_allclose(_wall_face_interpolate(kernel, grid, pos, u, 0)[z > 0.5 * h], 0.01, rtol=0, atol=1e-15)


@pytest.mark.parametrize("component", [0, 1, 2, 3])
def test_wall_faces_are_adjoint_and_give_the_wall_its_share(component):
    """With the walls' faces in the trilinear weights the two-step kernel stays adjoint, <D v, f> = <v, I f>, and
    the deposit falls short of the deposited total by exactly the wall faces' linear share, sum_p v_p (1 - s_p)
    over the droplets within a face spacing s_p < 1 of a wall they face (what the wall takes); cell arrays and
    periodic axes are unchanged."""
    periodic = (False, True, False)
    grid = Grid((12, 10, 14), 0.004, (0.1, -0.02, 0.0), periodic)
    kernel = filtered.FilteredKernel(grid.shape, periodic, 1.0)
    rng = np.random.default_rng(40 + component)
    lo, hi = np.asarray(grid.lower), grid.upper
    pos = lo + rng.uniform(0.0, 1.0, size=(120, 3)) * (hi - lo)
    pos[:30, component % 3] = lo[component % 3] + rng.uniform(0.0, 1.0, 30) * grid.spacing  # next to the lower wall
    values = rng.uniform(0.5, 2.0, 120)
    out = _wall_face_deposit(kernel, grid, pos, values, component)
    share = 0.0
    if component < 3 and not periodic[component]:
        s = (pos[:, component] - lo[component]) / grid.spacing
        n = grid.shape[component]
        share = np.sum(values * np.clip(1.0 - s, 0.0, 1.0)) + np.sum(values * np.clip(s - (n - 1), 0.0, 1.0))
        assert share > 1.0
    assert out.sum() == pytest.approx(values.sum() - share, rel=1e-13)
    field = rng.normal(size=out.shape)
    assert np.sum(out * field) == pytest.approx(np.sum(values * _wall_face_interpolate(kernel, grid, pos, field,
                                                                                          component)), rel=1e-12)


def test_near_wall_needs_the_filtered_kernel():
    """fulldem.near_wall = "wall" with the direct kernel is refused, naming both keys and what is allowed."""
    from fulldem.driver import check_case
    from settler.cases import CaseError, case_with_overrides

    case = case_with_overrides("demo", {"fulldem.near_wall": "wall", "fulldem.kernel": "direct"})
    with pytest.raises(CaseError, match=r"fulldem.near_wall = 'wall' with fulldem.kernel = 'direct'.*allowed"):
        check_case(case)
    with pytest.raises(CaseError, match=r"near_wall.*'floor'.*allowed"):
        case_with_overrides("demo", {"fulldem.near_wall": "floor"})


def test_filtered_kernel_width_matches_the_direct_gaussian():
    """Away from walls the filtered kernel's spread per axis, averaged over where the droplet sits in its cell, is
    sigma^2 = (sigma_cells h)^2 (0.1 %): the linear hat's h^2/6 plus the filter's sigma_g^2;
    and the self weight sum W^2 agrees with the deposit seen back at the droplet."""
    grid = Grid((16, 16, 16), 1.0, (0.0, 0.0, 0.0), (False, False, False))
    kernel = filtered.FilteredKernel(grid.shape, grid.periodic, 1.0)
    variances = []
    offsets = (np.arange(20) + 0.5) / 20  # evenly over the cell (the hat's variance f (1 - f) h^2 averages to h^2/6)
    for p in np.column_stack([7.5 + offsets, 7.5 + offsets[::-1], 7.5 + np.roll(offsets, 7)]):
        w = _filtered_deposit(kernel, grid, p[None, :], np.ones(1), 3)
        x = np.arange(16) + 0.5
        variances.append(np.sum(w.sum(axis=(1, 2)) * (x - p[0]) ** 2))
        own = np.zeros(1)
        kernel.self_weight(p[None, :], 1, 1.0, np.zeros(3), own)
        assert own[0] == pytest.approx(np.sum(w * w), rel=1e-12)
    assert np.mean(variances) == pytest.approx(1.0, rel=1e-3)


def test_filtered_kernel_self_mobility_factor():
    """The filtered kernel's self-mobility on the MAC grid (periodic FFT Stokes solve, images removed) is within
    10 % of the continuous Gaussian's 1/(6 pi^1.5 mu sigma), like the direct kernel's; the correction uses it."""
    assert filtered.filtered_mobility_factor(1.0) == pytest.approx(1.0, abs=0.1)
    assert filtered.filtered_mobility_factor(1.0) == pytest.approx(mobility.discrete_mobility_factor(1.0), rel=0.05)
