"""DEM part of the CFD-DEM engine: contact laws, neighbour lists, force kernels and the exponential integrator.

Tiers: laws against their formulas; the neighbour list against brute force; Numba kernels against their NumPy twins;
invariants (momentum, drag impulse); verification (restitution and peak overlap of a collision, terminal velocity and
trajectory under drag, the overlap of a settling pile).
"""

import decimal
import math
import time

import numba
import numpy as np
import pytest

from fulldem import tuning
from fulldem.dem import integrators
from fulldem.dem import laws as contacts
from fulldem.dem import neighbours as nb
from fulldem.dem import pairs, records
from fulldem.dem import stepper as dem_stepper
from fulldem.dem import twins as reference
from fulldem.dem import walls as dem_walls
from fulldem.droplets import COALESCING, DropletStore


RHO = 5100.0
DRHO = 5100.0 - 3150.0
MU = 0.45
G = 9.81


def _mass(d, rho=RHO):
    return rho * math.pi / 6.0 * d**3


# ------------------------------------------------------------------------------------------------ laws
@pytest.mark.parametrize("e", [0.1, 0.5, 0.9, 1.0])
def test_damping_ratio_formula_and_inverse(e):
    zeta = contacts.damping_ratio(e)
    assert zeta == pytest.approx(-math.log(e) / math.sqrt(math.pi**2 + math.log(e) ** 2), abs=1e-15)
    assert contacts.restitution_coefficient(zeta) == pytest.approx(e, rel=1e-13)


@pytest.mark.parametrize("name", list(contacts.CONTACT_LAWS))
def test_registered_laws_vanish_without_overlap_and_repel_when_compressed(name):
    law = contacts.CONTACT_LAWS[name]
    assert law.reference
    assert contacts.normal_force(law.code, 0.0, 0.0, 3.0, 0.1) == 0.0
    assert contacts.normal_force(law.code, 1e-6, 0.0, 3.0, 0.1) > 0.0
    assert contacts.normal_force(law.code, 1e-6, -1e-3, 3.0, 0.1) > contacts.normal_force(law.code, 1e-6, 0.0, 3.0,
                                                                                          0.1)
    with pytest.raises(ValueError, match="unknown contact law"):
        contacts.contact_law_code("nope")


def test_hooke_formula_and_benchmark_numbers():
    assert contacts.hooke_normal_force(2e-6, 3e-4, 5.0, 4e-4) == pytest.approx(5.0 * 2e-6 - 4e-4 * 3e-4, rel=1e-15)
    # benchmark-case.md: k_n = 5 N/m, e = 0.5, d = 0.5 mm, rho 5100: gamma_n/m_eff = 2358.5 1/s, t_c ~ 29 x 2e-5 s
    m_eff = contacts.effective_mass(_mass(0.5e-3), _mass(0.5e-3))
    gamma = contacts.damping_coefficient(5.0, m_eff, contacts.damping_ratio(0.5))
    assert gamma / m_eff == pytest.approx(2358.5, rel=1e-4)
    t_c = contacts.contact_time(5.0, m_eff)
    assert t_c / 2e-5 == pytest.approx(28.7, abs=0.1)
    assert contacts.stable_step(5.0, m_eff, steps_per_contact=t_c / 2e-5) == pytest.approx(2e-5, rel=1e-12)
    zeta = contacts.damping_ratio(0.5)
    assert contacts.contact_time(5.0, m_eff, zeta) == pytest.approx(t_c / math.sqrt(1 - zeta**2), rel=1e-14)
    with pytest.raises(ValueError):
        contacts.stable_step(5.0, m_eff, steps_per_contact=1.0)


def test_stiffness_for_overlap_and_size_scaling():
    d = 0.5e-3
    weight = DRHO * G * math.pi / 6 * d**3
    k = contacts.stiffness_for_overlap(0.02, d, DRHO, 40.0, G)
    assert k == pytest.approx(40 * weight / (0.02 * d), rel=1e-14)
    assert k == pytest.approx(5.0, rel=0.03)  # the benchmark's k_n is about 40 weights at 2 %
    # k_ij = k_ref (d_small/d_ref)^2 keeps the overlap ratio of a contact carrying its own droplet's weights
    for d_small in (0.35e-3, 2e-3, 40e-3):
        k_small = contacts.pair_stiffness(k, d, d_small)
        load = 40 * DRHO * G * math.pi / 6 * d_small**3
        assert load / k_small / d_small == pytest.approx(0.02, rel=1e-12)
    with pytest.raises(ValueError, match="max_overlap_ratio"):
        contacts.stiffness_for_overlap(0.0, d, DRHO, 1.0, G)


# ------------------------------------------------------------------------------------------------ neighbour lists
def _random_droplets(rng, n, box, periodic, large=()):
    """Random droplets 0.35-0.65 mm plus some large ones (they may overlap: a neighbour list does not care)."""
    pos = rng.uniform(0.0, 1.0, (n, 3)) * box
    d = rng.uniform(0.35e-3, 0.65e-3, n)
    d[: len(large)] = large
    for a in range(3):
        if not periodic[a]:  # some droplets slightly outside a bounded box (they are clamped into the end cells)
            pos[:3, a] = [-0.3e-3, box[a] + 0.2e-3, 0.5 * box[a]]
    return pos, d


@pytest.mark.parametrize("periodic", [(False, False, False), (True, True, True), (True, False, True)])
@pytest.mark.parametrize("half", [True, False])
def test_neighbour_list_matches_brute_force(periodic, half):
    rng = np.random.default_rng(7)
    box = np.array([0.006, 0.008, 0.007])
    pos, d = _random_droplets(rng, 700, box, periodic, large=(2e-3, 2e-3, 2.5e-3, 1.2e-3, 2.4e-3, 0.9e-3) * 2)
    skin = 0.125e-3
    nl = nb.NeighbourList((0, 0, 0), box, periodic, skin, half=half, index_capacity=8)
    nl.build(pos, d, len(d))
    i, j = nl.pairs()
    bi, bj = nb.brute_force_pairs(pos, d, len(d), skin, box, periodic)
    expected = set(zip(bi.tolist(), bj.tolist()))
    assert len(expected) > 500
    assert set(zip(np.minimum(i, j).tolist(), np.maximum(i, j).tolist())) == expected
    assert len(i) == (1 if half else 2) * len(expected)  # no duplicates
    assert np.all(i != j)
    assert nl.index.shape[0] >= len(i) and (nl.index.shape[0] & (nl.index.shape[0] - 1)) == 0  # grown by doubling


def test_one_pass_scan_with_cut_rows_matches_brute_force(monkeypatch):
    # rows wider than the scratch stride are cut and scanned again: force that on every build
    monkeypatch.setattr(nb, "MIN_ROW_STRIDE", 1)
    rng = np.random.default_rng(11)
    box = np.array([0.004, 0.004, 0.004])
    pos, d = _random_droplets(rng, 600, box, (False, True, False), large=(1.5e-3,))
    for half in (True, False):
        nl = nb.NeighbourList((0, 0, 0), box, (False, True, False), 0.2e-3, half=half)
        nl.build(pos, d, len(d))
        i, j = nl.pairs()
        assert nl.longest_row > 3
        bi, bj = nb.brute_force_pairs(pos, d, len(d), 0.2e-3, box, (False, True, False))
        assert set(zip(np.minimum(i, j).tolist(), np.maximum(i, j).tolist())) == set(zip(bi.tolist(), bj.tolist()))
        assert len(i) == (1 if half else 2) * len(bi)


def test_spatial_order_keeps_partners_close_in_a_flat_layer():
    # a wide, thin layer (the fed droplets under the roof): sorting with the vertical axis slowest would put a whole
    # layer of droplets between partners and leave the half-list kernels one slab per phase (one thread)
    rng = np.random.default_rng(5)
    n = 40000
    box = np.array([0.08, 0.08, 0.004])
    pos = rng.uniform(0.0, 1.0, (n, 3)) * box
    d = np.full(n, 0.5e-3)
    nl = nb.NeighbourList((0, 0, 0), box, (False, False, False), 0.125e-3)
    order = nl.spatial_order(pos, d, n)
    assert np.array_equal(np.sort(order), np.arange(n))
    nl.build(pos[order], d[order], n)
    # slabs of cells across the thin axis hold n/6 droplets each; across a wide axis about n/60
    assert nl.longest_jump < n // 20
    assert pairs.slab_count(n, nl.longest_jump) >= 8


@pytest.mark.parametrize("half", [True, False])
def test_neighbour_list_with_cells_numbered_along_another_axis_order(half):
    # a flat layer makes spatial_order number the cells with a wide axis slowest; later builds use that order
    rng = np.random.default_rng(13)
    box = np.array([0.012, 0.010, 0.002])
    periodic = (True, False, False)
    pos, d = _random_droplets(rng, 1500, box, periodic, large=(1.6e-3, 1.1e-3))
    nl = nb.NeighbourList((0, 0, 0), box, periodic, 0.125e-3, half=half)
    order = nl.spatial_order(pos, d, len(d))
    assert nl.axes[2] != 2  # z, the thin axis, is no longer the slowest
    pos, d = pos[order], d[order]
    nl.build(pos, d, len(d))
    i, j = nl.pairs()
    bi, bj = nb.brute_force_pairs(pos, d, len(d), 0.125e-3, box, periodic)
    assert len(bi) > 500
    assert set(zip(np.minimum(i, j).tolist(), np.maximum(i, j).tolist())) == set(zip(bi.tolist(), bj.tolist()))
    assert len(i) == (1 if half else 2) * len(bi)
    if half:
        assert np.mean(j > i) > 0.95  # cells numbered like the memory order: partners lie ahead


def test_neighbour_list_all_large_and_tiny_periodic_box():
    # every droplet larger than the cell diameter, and a periodic axis with only two cells
    rng = np.random.default_rng(3)
    box = np.array([0.006, 0.03, 0.03])
    pos = rng.uniform(0, 1, (150, 3)) * box
    d = rng.uniform(1e-3, 2.9e-3, 150)
    for half in (True, False):
        nl = nb.NeighbourList((0, 0, 0), box, (True, False, True), 0.1e-3, half=half, cell_diameter=0.5e-3)
        nl.build(pos, d, 150)
        i, j = nl.pairs()
        bi, bj = nb.brute_force_pairs(pos, d, 150, 0.1e-3, box, (True, False, True))
        assert set(zip(np.minimum(i, j).tolist(), np.maximum(i, j).tolist())) == set(zip(bi.tolist(), bj.tolist()))
        assert len(i) == (1 if half else 2) * len(bi)


def test_rebuild_criterion_and_periodic_wrap():
    box = np.array([0.01, 0.01, 0.01])
    pos = np.array([[0.001, 0.005, 0.005], [0.0095, 0.005, 0.005]])
    d = np.array([0.5e-3, 0.5e-3])
    nl = nb.NeighbourList((0, 0, 0), box, (True, True, True), 0.2e-3)
    assert nl.needs_rebuild(pos, d, 2)  # never built
    nl.build(pos, d, 2)
    assert not nl.needs_rebuild(pos, d, 2)
    moved = pos.copy()
    moved[1, 0] += 0.6e-3  # crosses the periodic boundary: 0.6 mm travelled, > skin/2
    nb.wrap_positions(moved, 2, np.zeros(3), nl.period)
    assert 0.0 <= moved[1, 0] < 0.01
    assert nl.needs_rebuild(moved, d, 2)
    small = pos.copy()
    small[1, 0] += 0.09e-3
    assert not nl.needs_rebuild(small, d, 2)
    grown = d.copy()
    grown[1] += 0.03e-3  # the moved droplet grows by 0.015 mm in radius: 0.09 + 0.015 > skin/2
    assert nl.needs_rebuild(small, grown, 2)
    assert nl.needs_rebuild(pos, d, 1)  # count changed


def test_reorder_store_keeps_droplets_and_partners():
    store = DropletStore(4)
    store.add(np.arange(15.0).reshape(5, 3), np.array([1.0, 2.0, 3.0, 4.0, 5.0]) * 1e-4, RHO)
    store.partner[:5] = [3, -1, -1, 0, -1]
    store.flags[[0, 3]] = COALESCING
    order = np.array([4, 3, 2, 1, 0])
    nb.reorder_store(store, order)
    assert store.ident[:5].tolist() == [4, 3, 2, 1, 0]
    assert store.diameter[1] == pytest.approx(4e-4)
    assert store.partner[:5].tolist() == [-1, 4, -1, -1, 1]


# ------------------------------------------------------------------------------------------------ kernels vs twins
NO_WALLS = records.walls_record(np.zeros(3), np.ones(3), (True, True, True), False, None, 0.0)


def _bodies(store, mass):
    return records.Bodies(store.diameter, mass, store.flags, store.partner)


def _full_list_forces(store, mass, nl, k_ref, d_ref, zeta, force, walls=NO_WALLS, nchunk=4):
    n = store.count
    candidates = np.zeros((nchunk, max(nl.longest_row, 1)), dtype=np.int32)
    damping = np.full(nl.index.shape[0], np.nan)
    pairs.pair_damping(nl.start, nl.index, store.diameter, mass, n, k_ref, d_ref, zeta, damping)
    return pairs.contact_forces_full(store.position, store.velocity, _bodies(store, mass), n,
                                   records.contacts_record(nl, damping, k_ref, d_ref, 0), walls, nchunk, candidates, force)


def _cluster(rng, n=50, periodic=(False, False, False)):
    """A cluster of droplets with many overlaps (a few per cent of d), random velocities, two coalescing couples."""
    box = np.array([2.2e-3, 2.2e-3, 2.6e-3])
    side = np.ceil(n ** (1 / 3)).astype(int)
    grid = np.stack(np.meshgrid(*(np.arange(side),) * 3, indexing="ij"), -1).reshape(-1, 3)[:n]
    pos = (grid + 0.5) * 0.48e-3 + rng.normal(0, 0.01e-3, (n, 3))
    d = rng.uniform(0.45e-3, 0.55e-3, n)
    vel = rng.normal(0, 1e-3, (n, 3))
    store = DropletStore(n)
    store.add(pos, d, RHO, velocity=vel)
    store.flags[[0, 1, 5, 9]] = COALESCING
    store.partner[[0, 1, 5, 9]] = [1, 0, 9, 5]
    store.flags[7] = COALESCING  # marked but not mutual: still repels
    store.partner[7] = 8
    mass = np.asarray(store.mass(), dtype=float)
    return store, box, mass


@pytest.mark.parametrize("periodic", [(False, False, False), (True, True, True)])
@pytest.mark.parametrize("half", [True, False])
def test_contact_kernels_match_numpy_twin(periodic, half):
    rng = np.random.default_rng(11)
    store, box, mass = _cluster(rng)
    n = store.count
    if periodic[0]:
        store.position[:n] -= 0.3e-3  # some droplets across the periodic boundary
        nb.wrap_positions(store.position, n, np.zeros(3), np.where(periodic, box, 0.0))
    nl = nb.NeighbourList((0, 0, 0), box, periodic, 0.1e-3, half=half)
    nl.build(store.position, store.diameter, n)
    zeta = contacts.damping_ratio(0.4)
    force = np.full((n, 3), np.nan)
    law = contacts.contact_law_code("hooke")
    if half:
        damping = np.full(nl.index.shape[0], np.nan)
        pairs.pair_damping(nl.start, nl.index, store.diameter, mass, n, 3.0, 0.5e-3, zeta, damping)
        nslab = pairs.slab_count(n, nl.longest_jump)
        worst = pairs.contact_forces_half(store.position, store.velocity, _bodies(store, mass), n,
                                        records.contacts_record(nl, damping, 3.0, 0.5e-3, law), NO_WALLS, nslab,
                                        np.zeros((nslab, nl.longest_row), dtype=np.int32), force)
    else:
        worst = _full_list_forces(store, mass, nl, 3.0, 0.5e-3, zeta, force)
    bi, bj = nb.brute_force_pairs(store.position, store.diameter, n, 0.0, box, periodic)
    ref, ref_worst = reference.contact_forces_reference(store.position, store.velocity, store.diameter, mass, store.flags,
                                                  store.partner, n, bi, bj, 3.0, 0.5e-3, zeta, law, nl.period)
    assert ref_worst > 0.02
    assert worst == pytest.approx(ref_worst, rel=1e-12)
    np.testing.assert_allclose(force, ref, rtol=1e-10, atol=1e-12 * np.abs(ref).max())
    # the mutual coalescing couple (0, 1) does not interact; the one-sided mark (7 -> 8) does not switch off contact
    delta = store.position[0] - store.position[1]
    delta -= nl.period * np.rint(delta * nl.inverse_period)
    assert np.linalg.norm(delta) < 0.5 * (store.diameter[0] + store.diameter[1])
    assert np.abs(force.sum(axis=0)).max() < 1e-13 * np.abs(force).max()


def test_half_list_slabs_agree_with_one_slab_and_with_the_full_list():
    # a few thousand spatially sorted droplets: several slabs run in parallel, each writing its partners' forces
    rng = np.random.default_rng(21)
    n = 4000
    box = np.array([0.006, 0.006, 0.03])
    store = DropletStore(n)
    store.add(rng.uniform(0, 1, (n, 3)) * box, rng.uniform(0.35e-3, 0.65e-3, n), RHO,
              velocity=rng.normal(0, 1e-3, (n, 3)))
    half = nb.NeighbourList((0, 0, 0), box, (False, False, False), 0.1e-3, half=True)
    nb.reorder_store(store, half.spatial_order(store.position, store.diameter, n))
    half.build(store.position, store.diameter, n)
    mass = np.asarray(store.mass(), dtype=float)
    damping = np.zeros(half.index.shape[0])
    pairs.pair_damping(half.start, half.index, store.diameter, mass, n, 3.0, 0.5e-3, 0.2, damping)
    safe = [s for s in range(2, pairs.MAX_SLABS + 1, 2) if n // s >= 2 * half.longest_jump + 1]
    assert len(safe) >= 2 and pairs.slab_count(n, half.longest_jump) == max(safe)
    assert pairs.slab_count(n, n // 3) == 1
    results = []
    for nslab in [1, *safe]:
        force = np.full((n, 3), np.nan)
        candidates = np.zeros((nslab, half.longest_row), dtype=np.int32)
        worst = pairs.contact_forces_half(store.position, store.velocity, _bodies(store, mass), n,
                                        records.contacts_record(half, damping, 3.0, 0.5e-3, 0), NO_WALLS, nslab,
                                        candidates, force)
        results.append((force, worst))
    full = nb.NeighbourList((0, 0, 0), box, (False, False, False), 0.1e-3, half=False)
    full.build(store.position, store.diameter, n)
    force_full = np.zeros((n, 3))
    worst_full = _full_list_forces(store, mass, full, 3.0, 0.5e-3, 0.2, force_full)
    scale = np.abs(force_full).max()
    assert worst_full > 0.01
    for force, worst in results:
        np.testing.assert_allclose(force, force_full, rtol=0, atol=1e-13 * scale)
        assert worst == pytest.approx(worst_full, rel=1e-14)


def test_coalescing_couple_exerts_no_force():
    store = DropletStore(2)
    store.add([[0.0, 0.0, 0.0], [0.45e-3, 0.0, 0.0]], 0.5e-3, RHO)
    mass = np.asarray(store.mass(), dtype=float)
    nl = nb.NeighbourList((-0.01,) * 3, (0.02,) * 3, (False,) * 3, 0.1e-3, half=False)
    nl.build(store.position, store.diameter, 2)
    force = np.zeros((2, 3))

    def run():
        return _full_list_forces(store, mass, nl, 5.0, 0.5e-3, 0.2, force, nchunk=1)

    run()
    assert force[0, 0] == pytest.approx(-5.0 * 0.05e-3, rel=1e-12)
    store.flags[:2] = COALESCING
    store.partner[:2] = [1, 0]
    assert run() == 0.0
    assert np.all(force == 0.0)


@pytest.mark.parametrize("absorbing_bottom", [False, True])
def test_wall_kernel_matches_numpy_twin(absorbing_bottom):
    rng = np.random.default_rng(5)
    n = 60
    box_lower, box_upper = np.zeros(3), np.array([4e-3, 3e-3, 5e-3])
    d = rng.uniform(0.35e-3, 0.65e-3, n)
    pos = rng.uniform(0, 1, (n, 3)) * box_upper
    pos[: n // 2, rng.integers(0, 3, n // 2)] *= 0.05  # many droplets pressed against lower walls
    pos[n // 2:, 0] = box_upper[0] - 0.15e-3  # and against the x+ wall, some inside the outlet hole
    vel = rng.normal(0, 1e-3, (n, 3))
    mass = _mass(d)
    periodic = np.array([False, True, False])
    outlet = (1, 2.5e-3, 1.5e-3, 1.2e-3)
    force = rng.normal(0, 1e-6, (n, 3))
    before = force.copy()
    worst = dem_walls.wall_forces(pos, vel, d, mass, n, records.walls_record(box_lower, box_upper, periodic, absorbing_bottom,
                                                                   outlet, 0.3), 2.0, 0.5e-3, 0, 4, force)
    ref, ref_worst = reference.wall_forces_reference(pos, vel, d, mass, n, box_lower, box_upper, periodic,
                                               absorbing_bottom, *outlet, 2.0, 0.5e-3, 0.3, 0)
    np.testing.assert_allclose(force - before, ref, rtol=1e-12, atol=1e-20)
    assert worst == pytest.approx(ref_worst, rel=1e-12)
    assert np.all(ref[:, 1] == 0.0)  # periodic axis: no walls
    in_hole = (pos[:, 2] - 2.5e-3) ** 2 + (pos[:, 1] - 1.5e-3) ** 2 < 1.2e-3**2
    assert in_hole[n // 2:].any() and (~in_hole[n // 2:]).any()
    assert np.all(ref[n // 2:][in_hole[n // 2:], 0] == 0.0)
    assert np.all(ref[n // 2:][~in_hole[n // 2:], 0] < 0.0)
    bottom = 0.5 * d - pos[:, 2] > 0
    assert bottom.any()
    assert np.all((ref[bottom, 2] == 0.0) == absorbing_bottom)


def test_full_list_kernel_applies_the_same_walls():
    rng = np.random.default_rng(8)
    store, box, mass = _cluster(rng, n=60)
    n = store.count
    store.position[:n] -= 0.15e-3  # pressed into the lower walls, and into an outlet in the x- wall
    periodic = np.array([False, False, False])
    nl = nb.NeighbourList((0, 0, 0), box, periodic, 0.1e-3, half=False)
    nl.build(store.position, store.diameter, n)
    geometry = (np.zeros(3), box, periodic, False, 0, 0.6e-3, 0.7e-3, 0.5e-3)
    fused = np.zeros((n, 3))
    planes = records.wall_planes(np.zeros(3), box, periodic, False)
    walls = records.walls_record(*geometry[:4], geometry[4:], 0.35)
    assert np.array_equal(walls.lower, planes[0]) and np.array_equal(walls.upper, planes[1])
    worst = _full_list_forces(store, mass, nl, 3.0, 0.5e-3, 0.25, fused, walls=walls)
    apart = np.zeros((n, 3))
    worst_pairs = _full_list_forces(store, mass, nl, 3.0, 0.5e-3, 0.25, apart)
    worst_walls = dem_walls.wall_forces(store.position, store.velocity, store.diameter, mass, n, walls, 3.0, 0.5e-3, 0, 2,
                                  apart)
    np.testing.assert_allclose(fused, apart, rtol=1e-13, atol=1e-14 * np.abs(apart).max())
    assert worst == max(worst_pairs, worst_walls) and worst_walls > 0.0


@pytest.mark.parametrize("uniform_fluid", [True, False])
def test_integrator_kernels_match_numpy_twin(uniform_fluid):
    rng = np.random.default_rng(2)
    n = 50
    pos, vel = rng.normal(0, 1e-3, (n, 3)), rng.normal(0, 1e-3, (n, 3))
    d = rng.uniform(0.3e-3, 3e-3, n)
    mass = _mass(d)
    beta = 3 * math.pi * MU * d
    beta[:5] = 0.0  # no drag
    fluid = rng.normal(0, 1e-3, (1, 3) if uniform_fluid else (n, 3))
    body = np.array([0.0, 0.0, -3.75])
    h = 2e-5
    force_old = rng.normal(0, 1e-6, (n, 3))

    def force_new_of(x, v):  # a position- and velocity-dependent force, to be evaluated at the new state
        return -2.0 * x - 1e-3 * v

    drag = np.zeros((n, 3))
    integrators.drag_factors_into(mass, beta, h, n, drag)
    x, v, impulse = pos.copy(), vel.copy(), np.zeros((n, 3))
    motion = records.Motion(drag, fluid, body, h, impulse)
    moved = integrators.integrate_initial(x, v, force_old, mass, motion, n, 3)
    force_new = force_new_of(x, v)
    integrators.integrate_final(v, force_new, mass, motion, n)
    x_ref, v_ref, j_ref = reference.integrate_reference(pos, vel, force_old, force_new_of, mass, beta, fluid, body, h, n)
    np.testing.assert_allclose(x, x_ref, rtol=1e-13, atol=1e-18)
    np.testing.assert_allclose(v, v_ref, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(impulse, j_ref, rtol=1e-9, atol=1e-12 * np.abs(mass[:, None] * vel).max())
    assert moved == pytest.approx(np.linalg.norm(x - pos, axis=1).max(), rel=1e-12)


@pytest.mark.parametrize("half_list", [True, False])
def test_advance_equals_repeated_steps_with_resorting(half_list):
    runs, peaks = [], []
    for fused in (False, True):
        store, _, _ = _cluster(np.random.default_rng(12), n=50)
        store.velocity[:50] *= 300.0  # fast enough to trigger rebuilds (and re-sorting) within the run
        stepper = dem_stepper.DemStepper(store, (0, 0, 0), (0.004, 0.004, 0.004), (True, False, True), 2e-5, 5.0, 0.5e-3,
                                 0.5, 0.05e-3, (0, 0, -3.75), half_list=half_list)
        stepper.droplets_changed()
        beta = 3 * math.pi * MU * store.diameter[:50]
        stepper.set_drag(beta)
        fluid = np.random.default_rng(0).normal(0, 1e-3, (50, 3))  # permuted with the droplets when they re-sort
        impulse = np.zeros((50, 3))
        if fused:
            stepper.advance(40, fluid, impulse)
            peak = stepper.peak_overlap_ratio
        else:
            peak = 0.0
            for _ in range(40):
                stepper.step(fluid, impulse)
                peak = max(peak, stepper.max_overlap_ratio)
        assert stepper.neighbours.builds > 1
        runs.append((store.ident[:50].copy(), store.position[:50].copy(), store.velocity[:50].copy(), impulse))
        peaks.append(peak)
    order = np.argsort(runs[0][0]), np.argsort(runs[1][0])
    for a in range(1, 4):
        np.testing.assert_allclose(runs[1][a][order[1]], runs[0][a][order[0]], rtol=1e-12, atol=1e-20)
    # the largest overlap over the advance's steps, not only the last step's
    assert peaks[0] > 0.0 and peaks[1] == pytest.approx(peaks[0], rel=1e-9)


def test_results_do_not_depend_on_the_thread_count():
    rng = np.random.default_rng(5)
    n = 2500  # above PARALLEL_MIN_DROPLETS
    assert n >= tuning.PARALLEL_MIN_DROPLETS
    box = np.array([0.006, 0.006, 0.03])
    pos = rng.uniform(0, 1, (n, 3)) * box
    d = rng.uniform(0.35e-3, 0.65e-3, n)
    vel = rng.normal(0, 0.05, (n, 3))
    states = []
    for threads in (1, 2, None):
        store = DropletStore(n)
        store.add(pos, d, RHO, velocity=vel)
        stepper = dem_stepper.DemStepper(store, (0, 0, 0), box, (True, True, False), 2e-5, 5.0, 0.5e-3, 0.5, 0.1e-3,
                                 (0, 0, -3.75), threads=threads)
        stepper.droplets_changed()
        stepper.set_drag(3 * math.pi * MU * store.diameter)
        stepper.advance(4 * tuning.THREAD_PROBE_STEPS + 7, np.zeros((1, 3)), dem_stepper.NO_IMPULSE)
        order = np.argsort(store.ident[:n])
        states.append((store.position[:n][order], store.velocity[:n][order], stepper.neighbours.builds))
    # fixed thread counts agree bit for bit, and so does the timed choice, which runs an advance shorter than
    # THREAD_PROBE_EVERY whole on one count
    assert 4 * tuning.THREAD_PROBE_STEPS + 7 < tuning.THREAD_PROBE_EVERY
    for position, velocity, _ in states[1:]:
        np.testing.assert_array_equal(position, states[0][0])
        np.testing.assert_array_equal(velocity, states[0][1])
    assert min(builds for _, _, builds in states) > 1


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two Numba threads")
def test_timed_thread_choice_times_short_advances_whole():
    """ThreadChoice(None) on advances shorter than THREAD_PROBE_EVERY: the first on all threads (untimed: it may
    compile), then one timed on all and one on a single thread, the faster for THREAD_PROBE_WHOLE_EVERY steps, then
    timed again; no advance is split. The fake advance is slow on two threads, so one is chosen."""
    threads = min(2, numba.config.NUMBA_NUM_THREADS)
    numba.set_num_threads(threads)
    seen = []

    def advance(k):
        seen.append((numba.get_num_threads(), k))
        time.sleep(0.02 if numba.get_num_threads() > 1 else 0.0)  # 20 ms: beyond a loaded machine's jitter
        return None

    choice = tuning.ThreadChoice(None)
    steps = 71
    calls = 3 + tuning.THREAD_PROBE_WHOLE_EVERY // steps + 3
    for _ in range(calls):
        choice.run(tuning.PARALLEL_MIN_DROPLETS, steps, advance)
    assert all(k == steps for _, k in seen)  # whole advances
    used = [t for t, _ in seen]
    assert used[:3] == [threads, threads, 1] and choice.timed == 1
    again = 3 + math.ceil(tuning.THREAD_PROBE_WHOLE_EVERY / steps)  # the first call after the interval
    assert set(used[3:again]) == {1} and used[again:again + 2] == [threads, 1]
    assert numba.get_num_threads() == threads  # put back


def test_drag_factors_series_and_exponential_branches_agree():
    decimal.getcontext().prec = 40  # the reference in 40-digit decimal arithmetic
    h = 1.0
    for z in (0.0, 1e-12, 1e-6, 0.1, 0.4999999, 0.5, 0.5000001, 3.0, 40.0):
        e, phi1, phi2 = integrators.drag_factors(z, h)
        if z == 0.0:
            assert (e, phi1, phi2) == (1.0, 1.0, 0.5)
            continue
        zz = decimal.Decimal(z)
        decay = (-zz).exp()
        assert e == pytest.approx(float(decay), rel=1e-15)
        assert phi1 == pytest.approx(float((1 - decay) / zz), rel=4e-16)
        assert phi2 == pytest.approx(float((zz - 1 + decay) / zz**2), rel=2e-15)


# ------------------------------------------------------------------------------------------------ verification
def _stepper(store, h, k, restitution, periodic=(True, True, True), box=0.01, body=(0.0, 0.0, 0.0), **kw):
    stepper = dem_stepper.DemStepper(store, (0.0, 0.0, 0.0), (box,) * 3, periodic, h, k, 0.5e-3, restitution, 0.1e-3,
                             body, **kw)
    stepper.droplets_changed()
    return stepper


@pytest.mark.parametrize("d_pair, e", [((0.5e-3, 0.5e-3), 0.5), ((0.4e-3, 0.6e-3), 0.5), ((0.5e-3, 0.5e-3), 0.9)])
def test_head_on_collision_restitution_and_peak_overlap_in_vacuum(d_pair, e):
    d1, d2 = d_pair
    speed = 1e-3  # each droplet, towards the other
    store = DropletStore(2)
    store.add([[0.005 - 0.5 * d1 - 2e-6, 0.005, 0.005], [0.005 + 0.5 * d2 + 2e-6, 0.005, 0.005]], [d1, d2], RHO,
              velocity=[[speed, 0, 0], [-speed, 0, 0]])
    k_ref = 5.0
    m_eff = contacts.effective_mass(_mass(d1), _mass(d2))
    k = contacts.pair_stiffness(k_ref, 0.5e-3, min(d1, d2))
    h = contacts.stable_step(k, m_eff, steps_per_contact=30)
    stepper = _stepper(store, h, k_ref, e, sort_on_rebuild=False)
    stepper.set_drag(np.zeros(2))  # vacuum: beta = 0
    peak = 0.0
    still = np.zeros((1, 3))
    p0 = _mass(d1) * store.velocity[0] + _mass(d2) * store.velocity[1]
    for _ in range(200):
        stepper.step(still, dem_stepper.NO_IMPULSE)
        gap = store.position[1, 0] - store.position[0, 0] - 0.5 * (d1 + d2)
        peak = max(peak, -gap)
    approach = 2 * speed
    separation = store.velocity[1, 0] - store.velocity[0, 0]
    assert gap > 0  # contact over
    assert separation / approach == pytest.approx(e, rel=0.02)
    zeta = contacts.damping_ratio(e)
    omega = math.sqrt(k / m_eff)
    root = math.sqrt(1 - zeta**2)
    analytic = approach / omega * math.exp(-zeta / root * math.atan2(root, zeta))
    assert peak == pytest.approx(analytic, rel=0.02)
    p1 = _mass(d1) * store.velocity[0] + _mass(d2) * store.velocity[1]
    assert np.abs(p1 - p0).max() < 1e-14 * _mass(d1) * speed


@pytest.mark.parametrize("ratio", [10.0, 0.1])
def test_exponential_step_reaches_terminal_velocity_and_follows_analytic_trajectory(ratio):
    d = 0.5e-3
    beta = 3 * math.pi * MU * d
    m = _mass(d)
    tau = m / beta
    h = ratio * tau
    g = np.array([0.0, 0.0, -3.7509])
    u = np.array([2e-4, -1e-4, 3e-4])
    store = DropletStore(1)
    store.add([[0.005, 0.005, 0.005]], d, RHO)
    stepper = _stepper(store, h, 5.0, 0.5, box=0.01, body=g)
    stepper.set_drag(np.array([beta]))
    impulse = np.zeros((1, 3))
    steps = int(round(60 * tau / h)) if ratio < 1 else 8
    for _ in range(steps):
        stepper.step(u[None, :], impulse)
    terminal = u + g * tau
    np.testing.assert_allclose(store.velocity[0], terminal, rtol=1e-12, atol=1e-12 * np.abs(terminal).max())
    t = steps * h
    # x(t) = x0 + (u + g tau) t - g tau^2 (1 - e^{-t/tau}) (from rest) - u tau (1 - e^{-t/tau}), unwrapped
    expected = 0.005 + terminal * t - (g * tau + u) * tau * (-math.expm1(-t / tau))
    travelled = store.position[0] - 0.005
    np.testing.assert_allclose(travelled, expected - 0.005, rtol=1e-12, atol=1e-15)
    # the drag impulse is beta * integral(u - v) = m v(t) - m g t from rest
    np.testing.assert_allclose(impulse[0], m * store.velocity[0] - m * g * t, rtol=1e-10, atol=1e-12 * m * 1e-3)


def test_closed_set_conserves_momentum_to_round_off():
    rng = np.random.default_rng(4)
    store, _, mass = _cluster(rng, n=64)
    store.flags[:] = 0
    store.partner[:] = -1
    box_size = 0.01
    stepper = _stepper(store, 1e-5, 5.0, 0.3, box=box_size, half_list=False)
    stepper.set_drag(np.zeros(store.count))
    mass = stepper.mass[: store.count, None]
    p0 = (mass * store.velocity[: store.count]).sum(axis=0)
    scale = (mass * np.abs(store.velocity[: store.count])).sum()
    still = np.zeros((1, 3))
    for _ in range(300):
        stepper.step(still, dem_stepper.NO_IMPULSE)
        f = stepper.force[: store.count]
        assert np.abs(f.sum(axis=0)).max() <= 1e-13 * np.abs(f).sum()
    p1 = (mass * store.velocity[: store.count]).sum(axis=0)
    assert np.abs(p1 - p0).max() < 1e-13 * scale
    assert stepper.max_overlap_ratio > 0.0


def test_drag_impulse_bookkeeping_with_contacts_and_walls():
    rng = np.random.default_rng(9)
    store, box, _ = _cluster(rng, n=50)
    store.position[: store.count] += 0.2e-3
    stepper = dem_stepper.DemStepper(store, (0, 0, 0), box, (False, True, False), 2e-5, 5.0, 0.5e-3, 0.5, 0.1e-3,
                             (0, 0, -3.75), sort_on_rebuild=False)
    stepper.droplets_changed()
    n = store.count
    beta = 3 * math.pi * MU * store.diameter[:n]
    stepper.set_drag(beta)
    fluid = rng.normal(0, 1e-3, (n, 3))
    mass = stepper.mass[:n, None]
    for _ in range(5):
        v0 = store.velocity[:n].copy()
        a0 = stepper.force[:n] / mass + stepper.body_acceleration
        impulse = np.zeros((n, 3))
        stepper.step(fluid, impulse)
        a1 = stepper.force[:n] / mass + stepper.body_acceleration
        expected = mass * (store.velocity[:n] - v0) - mass * stepper.dem_step * 0.5 * (a0 + a1)
        scale = np.abs(mass * v0).max() + np.abs(mass * a0 * stepper.dem_step).max()
        np.testing.assert_allclose(impulse, expected, rtol=0, atol=1e-13 * scale)
        # momentum: what the droplets gained beyond body forces and walls is what the drag gave them
        wall_force = stepper.force[:n].sum(axis=0)  # contact forces sum to zero; the rest is walls
        gained = (mass * (store.velocity[:n] - v0)).sum(axis=0)
        assert np.abs(gained - impulse.sum(axis=0) - stepper.dem_step * (mass * stepper.body_acceleration).sum(axis=0)
                      ).max() < 1e-3 * scale + np.abs(wall_force).max() * stepper.dem_step


def test_dense_settling_pile_overlap_stays_below_two_percent():
    """Acceptance: in a dense settling cluster the largest overlap stays under 2 % of the smaller diameter.

    300 droplets 0.35-0.65 mm in slag (Stokes drag) settle onto a wall floor in a laterally periodic column of
    3.5 mm x 3.5 mm (about six layers). Stiffness from the overlap target (:func:`contacts.stiffness_for_overlap`):
    1 % for the column's average load on the smallest droplet -- the force chains of a pile carry about twice the
    average (here 36 against 17.5 weights), hence half the 2 % limit. The approach to the pile is run with gravity
    and stiffness both x100 (in drag-dominated settling this only compresses time: the same static overlaps), then
    20 ms with the real values.
    """
    rng = np.random.default_rng(3)
    n, side = 300, 3.5e-3
    d = rng.uniform(0.35e-3, 0.65e-3, n)
    pos = np.zeros((n, 3))
    placed = 0
    while placed < n:
        p = rng.uniform([0, 0, 0], [side, side, 6e-3])
        p[2] += 0.5 * d[placed]
        delta = pos[:placed] - p
        delta[:, :2] -= side * np.rint(delta[:, :2] / side)
        if np.all(np.einsum("ij,ij->i", delta, delta) > (0.5 * (d[:placed] + d[placed])) ** 2):
            pos[placed] = p
            placed += 1
    layers = n * np.mean(d**3) / (side * side * 0.6) * math.pi / 6 / np.mean(d)
    d_small = d.min()
    load = layers * (np.mean(d) / d_small) ** 3  # the column's weight on the smallest droplet, in its weights
    k_ref = contacts.stiffness_for_overlap(0.01, d_small, DRHO, load, G)
    store = DropletStore(n)
    store.add(pos, d, RHO)
    still = np.zeros((1, 3))
    worst = {}
    for label, speed_up, duration in (("approach", 100.0, 0.12), ("real", 1.0, 0.02)):
        k = k_ref * speed_up
        h = contacts.stable_step(k, contacts.effective_mass(_mass(d_small), _mass(d_small)))
        stepper = dem_stepper.DemStepper(store, (0, 0, 0), (side, side, 0.05), (True, True, False), h, k, d_small, 0.5,
                                 0.25 * 0.5e-3, (0, 0, -G * speed_up * DRHO / RHO))
        stepper.droplets_changed()
        stepper.set_drag(3 * math.pi * MU * store.diameter)
        worst[label] = 0.0
        for _ in range(int(duration / h)):
            stepper.step(still, dem_stepper.NO_IMPULSE)
            worst[label] = max(worst[label], stepper.max_overlap_ratio)
    assert store.position[:n, 2].max() < 0.5 * (6e-3 + 0.65e-3)  # it settled into a pile ...
    assert np.abs(store.velocity[:n]).max() < 3e-4  # ... whose droplets move at under half the settling speed
    assert 0.005 < worst["real"] < 0.02
    assert worst["approach"] < 0.02


# ------------------------------------------------------------------------------------------------ threading layer
def test_fulldem_prefers_openmp_over_tbb_threading_layer():
    """Importing fulldem makes numba launch OpenMP (or workqueue) threads, not TBB, whose launch cost grows over a
    long run (see the docstring of :mod:`fulldem`); an explicit environment setting is left alone."""
    import os
    import subprocess
    import sys

    script = ("import numpy as np, numba, fulldem\n"
              "@numba.njit(parallel=True)\n"
              "def fill(a):\n"
              "    for i in numba.prange(a.size):\n"
              "        a[i] = i\n"
              "fill(np.zeros(8))\n"
              "print(numba.threading_layer())\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_THREADING_LAYER")}
    layer = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
    assert layer.stdout.strip() in ("omp", "workqueue")
    env["NUMBA_THREADING_LAYER"] = "workqueue"
    layer = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
    assert layer.stdout.strip() == "workqueue"
