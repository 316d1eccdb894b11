"""The coalescence submodel (seed paper section 3.3.1) against its definition and conservation laws.

References: the first contact's approach speed is the relative speed of two droplets closing in a vacuum (exact);
the merged droplet conserves volume (d^3 summed), mass, momentum and Cu2S exactly; grown sizes never reach the fluid
(the deposited droplet volume equals the true volumes at every step, to round-off); the size limit and the P_c
threshold refuse what they must; a run repeats bit for bit.
"""

import math

import numba
import numpy as np
import pytest

from fulldem.dem import records
from fulldem.dem import stepper as dem_stepper
from fulldem.cases.bidisperse import at_time, bidisperse_suspension, growth_time, settle_against_ballistic_kernel
from fulldem.droplets import COALESCING, MERGED, DropletStore
from fulldem.stepper import Simulation
from fulldem.submodels.coalescence import SIZE_BINS, size_bin
from settler.cases import load_case
from settler.physics import coalescence_probability


BOX = 0.04
SMALL_BOX = ["feed.mass_rate=0", "fulldem.cell_size=0.005", "fulldem.fluid_step=0.002"]


@pytest.mark.parametrize("half", [True, False])
def test_first_contact_records_the_approach_speed_once(half):
    """Two droplets closing at 0.05 m/s with no drag and no gravity: the record holds the pair once, with the
    closing speed (exact: nothing acts before they touch), and nothing is recorded while they stay in contact."""
    store = DropletStore(8)
    d = 0.5e-3
    store.add([[2e-3, 2e-3, 2e-3], [2e-3 + d + 2e-5, 2e-3, 2e-3]], d, 5000.0,
              velocity=[[0.03, 0.0, 0.0], [-0.02, 0.0, 0.0]])
    stepper = dem_stepper.DemStepper(store, (0, 0, 0), (4e-3,) * 3, (False, False, False), 1e-5, 5.0, d, 0.5, 0.1e-3,
                             (0, 0, 0), half_list=half, record_first_contacts=True)
    stepper.droplets_changed()
    stepper.set_drag(np.zeros(store.capacity))
    fluid = np.zeros((1, 3))
    a, b, speed = stepper.take_first_contacts()
    assert a.size == 0
    stepper.advance(20, fluid, dem_stepper.NO_IMPULSE)  # 20 um gap at 0.05 m/s: touching after 40 steps
    assert stepper.take_first_contacts()[0].size == 0
    stepper.advance(30, fluid, dem_stepper.NO_IMPULSE)
    a, b, speed = stepper.take_first_contacts()
    assert sorted({int(a[0]), int(b[0])}) == [0, 1] and a.size == (1 if half else 2)
    assert speed == pytest.approx(0.05, rel=1e-12)
    stepper.advance(10, fluid, dem_stepper.NO_IMPULSE)  # still in contact: no new first contact
    assert stepper.take_first_contacts()[0].size == 0


def _two_droplets(extra=(), large=1.0e-3, small=0.5e-3):
    """A large droplet 1 mm above a small one in quiescent slag: it settles faster and catches up."""
    case = load_case("simple", [*SMALL_BOX, *extra])
    store = DropletStore(16)
    store.add([[0.02, 0.02, 0.03], [0.02, 0.02, 0.03 - 1.0e-3]], [large, small], 5100.0, age=[1.0, 3.0])
    return Simulation(case, droplets=store, feed=False, box=((BOX,) * 3, (0.0, 0.0, 0.0)))


def _deposited_volume(sim):
    """The droplet volume the fluid sees: the integral of 1 - eps over the cells [m^3]."""
    cells = sim.void_fraction()[1]
    return float(np.sum(1.0 - cells) * sim.grid.cell_volume)


def test_a_pair_is_marked_grows_and_merges_conserving_everything(monkeypatch):
    sim = _two_droplets()
    s = sim.store
    before = {}
    merge = s.merge

    def spy(first, second, *periodic):  # the state the merge starts from, at the event point
        before.update(position=s.position[:2].copy(), velocity=s.velocity[:2].copy(), age=s.age[:2].copy())
        return merge(first, second, *periodic)

    monkeypatch.setattr(s, "merge", spy)
    d = s.diameter[:2].copy()
    mass = s.density[:2] * math.pi / 6 * d**3
    true_volume = math.pi / 6 * float(np.sum(d**3))
    marked_at = grown = None
    for step in range(400):
        sim.step()
        if s.count == 2 and (s.flags[0] & COALESCING):
            marked_at = marked_at if marked_at is not None else step
            assert s.partner[0] == 1 and s.partner[1] == 0
            # grown sizes are for contacts only: the fluid sees the true volumes
            assert _deposited_volume(sim) == pytest.approx(true_volume, rel=1e-12)
            assert np.array_equal(s.diameter[:2], d)
            grown = s.contact_diameter[1]
        if s.count == 1:
            break
    assert marked_at is not None and grown > 1.5 * d[1]
    assert s.count == 1 and sim.counters.merges == 1
    merged = (d[0] ** 3 + d[1] ** 3) ** (1 / 3)
    assert s.diameter[0] == pytest.approx(merged, rel=1e-14)
    assert s.contact_diameter[0] == s.diameter[0] and s.flags[0] == MERGED and s.partner[0] == -1
    assert s.density[0] * math.pi / 6 * s.diameter[0] ** 3 == pytest.approx(mass.sum(), rel=1e-14)
    # the merge at the event point: centre of mass, summed momentum and mass x age of the state just before it
    pos, vel, age = before["position"], before["velocity"], before["age"]
    w = mass / mass.sum()
    np.testing.assert_allclose(s.position[0], w @ pos, rtol=1e-14)
    np.testing.assert_allclose(s.velocity[0], w @ vel, rtol=1e-12)
    assert s.age[0] == pytest.approx(w @ age, rel=1e-14)
    assert _deposited_volume(sim) == pytest.approx(true_volume, rel=1e-12)
    table = sim.counters.merges_by_size
    assert table.sum() == 1 and table[size_bin(d[1]), size_bin(d[0])] == 1
    assert SIZE_BINS[size_bin(d[1]) - 1] <= d[1] < SIZE_BINS[size_bin(d[1])]


@pytest.mark.parametrize("extra", [["coalescence.size_limit=1.03e-3"],
                                   ["coalescence.threshold=1.0", "coalescence.trigger=first_contact"]],
                         ids=["size_limit", "threshold"])
def test_no_merge_beyond_the_size_limit_or_below_the_threshold(extra):
    """The merged droplet would be 1.040 mm: a 1.03 mm limit refuses it (under the default trigger, every contact
    evaluated). P_c < 1 at any approach speed above 0, so a threshold of 1 refuses a pair evaluated at its first
    contact, when it closes at its settling-speed difference (under 'every_contact' the pair, once resting in
    contact, has approach speed 0 and P_c = 1, which a threshold of 1 admits: the resting-pair test below). The
    droplets then touch and push each other as without coalescence."""
    sim = _two_droplets(extra)
    s = sim.store
    touched = False
    for _ in range(300):
        sim.step()
        gap = np.linalg.norm(s.position[0] - s.position[1]) - 0.5 * (s.diameter[0] + s.diameter[1])
        touched |= gap < 0.0
        assert s.count == 2 and not (s.flags[:2] & COALESCING).any()
    assert touched and sim.counters.merges == 0
    # and the pair's probability was indeed below 1 (the threshold case is not vacuous)
    assert coalescence_probability(1e-3, 0.5e-3, 1e-3, 5100.0, 3150.0, 0.5) < 1.0


def test_instantaneous_mode_merges_at_first_contact():
    sim = _two_droplets(["coalescence.mode=instantaneous"])
    s = sim.store
    for _ in range(300):
        sim.step()
        assert not (s.flags[: s.count] & COALESCING).any()  # never marked
        if s.count == 1:
            break
    assert s.count == 1 and sim.counters.merges == 1 and s.flags[0] == MERGED


@pytest.mark.parametrize("trigger, merges", [("every_contact", 1), ("first_contact", 0)])
def test_a_pair_resting_in_contact_merges_only_when_every_contact_is_evaluated(trigger, merges):
    """Two equal droplets side by side, touching (overlap 1e-4 d) and at rest, settle together: they never make a
    first contact, so under 'first_contact' they are never evaluated; under 'every_contact' their approach speed is
    0, so P_c = 1 >= 0.5 (seed Eq. 2 at Weber number 0), the merged 0.63 mm is within the 1.5 mm limit, and they are
    marked at the first event point and merge once grown (0.08 s at growth_rate 2) and drawn together."""
    d = 0.5e-3
    case = load_case("simple", [*SMALL_BOX, f"coalescence.trigger={trigger}"])
    assert coalescence_probability(d, d, 0.0, 5100.0, case.slag.density, case.matte.interfacial_tension,
                                   case.coalescence.psi, case.coalescence.virtual_mass) >= case.coalescence.threshold
    store = DropletStore(16)
    half = 0.5 * d * (1.0 - 1e-4)
    store.add([[0.02 - half, 0.02, 0.03], [0.02 + half, 0.02, 0.03]], d, 5100.0)
    sim = Simulation(case, droplets=store, feed=False, box=((BOX,) * 3, (0.0, 0.0, 0.0)))
    for _ in range(100):  # 0.2 s
        sim.step()
    assert sim.counters.merges == merges
    assert store.count == 2 - merges


def test_a_marked_pair_settling_at_different_speeds_merges_within_its_growth_time():
    """A 1.5 mm droplet falls onto a 0.5 mm one below it (5.5 mm/s faster). Once marked they no longer push each
    other, so the large one falls on through the small one: the draw must follow their differential settling, or
    the pair drifts apart and stays marked (the delayed merge's failure in dilute settling). It merges within its
    growth time (the smaller partner's contact diameter growing to growth_target x d_m at growth_rate x d_m per
    second) plus one fluid step after it was marked."""
    case = load_case("simple", [*SMALL_BOX, "coalescence.size_limit=4e-3"])
    large, small = 1.5e-3, 0.5e-3
    store = DropletStore(16)
    store.add([[0.02, 0.02, 0.03 + 1.2e-3], [0.02, 0.02, 0.03]], [large, small], 5100.0)
    sim = Simulation(case, droplets=store, feed=False, box=((BOX,) * 3, (0.0, 0.0, 0.0)))
    merged = (large**3 + small**3) ** (1.0 / 3.0)
    c = case.coalescence
    growth_steps = math.ceil((c.growth_target * merged - small) / (c.growth_rate * sim.dt * merged))
    marked_at = None
    for step in range(400):
        sim.step()
        if marked_at is None and (store.flags[: store.count] & COALESCING).any():
            marked_at = step
        if sim.counters.merges:
            break
    assert marked_at is not None and sim.counters.merges == 1
    assert step - marked_at <= growth_steps + 1


def test_in_dilute_settling_no_marked_pair_waits_past_its_growth_time():
    """The regime of the channel: 1.5 mm droplets settling through 0.5 mm ones. Every pair the delayed merge marks
    merges within its growth time plus one fluid step (``pairs_waiting`` stays 0), so marks turn into merges at the
    rate they are made; before the draw followed the partners' differential settling, nearly every mark waited for
    the rest of the run (1 merge of 465 marks' worth in 3 s in the coalescence issue's report)."""
    sim, _ = bidisperse_suspension(120, 1500, (0.04, 0.04, 0.06), large_bottom=0.036)
    coalescence = next(m for m in sim.submodels if m.name == "coalescence")
    waiting = 0
    for _ in range(1500):  # 3 s
        sim.step()
        waiting = max(waiting, coalescence.columns(sim)["pairs_waiting"])
    marked_now = int(((sim.store.flags[: sim.store.count] & COALESCING) != 0).sum()) // 2
    assert sim.counters.marks >= 40  # enough collisions for the statement to mean something (36 in the first 1.5 s)
    assert waiting == 0
    assert sim.counters.merges == sim.counters.marks - marked_now  # every other mark has merged


@pytest.fixture(scope="module")
def dilute_settling():
    """800 droplets of 1.5 mm falling through 2060 of 0.5 mm for 4 s in a closed 60 x 60 x 80 mm box (the large
    ones 0.9 % of the volume they start in, one merge for every second or third of them): the instantaneous and
    the delayed merge (the case's growth rate and trigger) against the ballistic kernel, as
    benchmarks/study_coalescence_kernel.py runs them."""
    out = {}
    for mode in ("instantaneous", "delayed"):
        sim, region = bidisperse_suspension(800, 2060, (0.06, 0.06, 0.08), large_bottom=0.03,
                                            extra=[f"coalescence.mode={mode}"])
        out[mode] = (sim, settle_against_ballistic_kernel(sim, region, 4.0))
    return out


@pytest.mark.parametrize("mode", ["instantaneous", "delayed"])
def test_merges_in_dilute_settling_follow_the_ballistic_kernel(dilute_settling, mode):
    """The large-small merges counted by merges_by_size against the ballistic differential-settling kernel
    pi (a_l + a_s)^2 |dU| n_s N_l integrated over the run (every contact merges: threshold 0), with the counts,
    sizes and velocities relative to the slag the run itself has (fulldem.cases.bidisperse), within 15 %. A delayed
    merge completes its growth time (0.312 s) after the contact, so its merges at 4 s are compared with the
    contacts expected by 4 s less that time. Measured: instantaneous 354 against 340 (+4 %), delayed 327 against
    320 (+2 %); before the draw followed the partners' differential settling, the delayed merge made one merge in
    a run like this."""
    sim, result = dilute_settling[mode]
    lag = growth_time(sim.case) if mode == "delayed" else 0.0
    expected = at_time(result, "expected", 4.0 - lag)
    assert result["merged"][-1] >= 250  # a few hundred merges: the Poisson scatter is ~6 %
    assert abs(result["merged"][-1] / expected - 1.0) < 0.15


def test_the_delayed_merge_keeps_the_instantaneous_rate_in_dilute_settling(dilute_settling):
    """Delayed within 10 % of instantaneous: the delayed run's large-small merges at 4 s against the instantaneous
    run's by 4 s less the growth time (the contacts the delayed run has had time to complete). What the delayed
    merge loses is the growth time itself, during which a marked droplet cannot be marked again: about the
    collision rate (0.12 per second for a large droplet here) times 0.31 s, 4 %. Measured: 327 against 329."""
    delayed = dilute_settling["delayed"][1]["merged"][-1]
    sim, result = dilute_settling["instantaneous"]
    instantaneous = at_time(result, "merged", 4.0 - growth_time(sim.case))
    assert abs(delayed / instantaneous - 1.0) < 0.10
    assert dilute_settling["delayed"][1]["waiting"] == 0


def _cloud(threads):
    """294 droplets of 0.6-1.6 mm in a periodic box whose pressure gradient carries their weight: many
    collisions and merges in 60 steps."""
    case = load_case("simple", [*SMALL_BOX, "coalescence.size_limit=4e-3", "coalescence.growth_rate=20"])
    rng = np.random.default_rng(7)
    size, spacing = 0.03, 1.8e-3
    lattice = np.stack(np.meshgrid(*(np.arange(7),) * 2, np.arange(6), indexing="ij"), -1).reshape(-1, 3)
    n = len(lattice)
    store = DropletStore(512)  # on a jittered lattice: no overlaps at the start, gaps of 0.1-1.2 mm
    store.add((lattice + 1.0) * spacing + rng.uniform(-0.05e-3, 0.05e-3, (n, 3)), rng.uniform(0.6e-3, 1.6e-3, n),
              5100.0, velocity=rng.normal(0.0, 0.01, (n, 3)), age=rng.uniform(0.0, 5.0, n))
    weight = np.sum((5100.0 - 3150.0) * math.pi / 6 * store.diameter[:n] ** 3) * 9.80665
    numba.set_num_threads(threads)
    try:
        sim = Simulation(case, droplets=store, feed=False, box=((size,) * 3, (0.0, 0.0, 0.0)),
                         periodic=(True, True, True), body_force=(0.0, 0.0, weight / size**3))
        sim.step()
        start, scale = sim.momentum(), np.sum(np.abs(sim.impulse[: sim.store.count]))
        mass0 = float(np.sum(store.mass()))
        cu0 = float(np.sum(store.original_diameter[: store.count] ** 3))
        for _ in range(150):
            sim.step()
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    return sim, start, scale, mass0, cu0


def test_merges_in_a_cloud_conserve_momentum_and_matte_and_repeat_exactly():
    """Many merges in a settling cloud: the total momentum stays constant to round-off, matte mass and Cu2S are
    conserved, and a second run with the same seed on the same threads (two, where there are two) is identical bit
    for bit. (One and two threads agree only to round-off, 1e-18 m here, with or without coalescence: some of the
    fluid solver's sums are split by thread.)"""
    threads = min(2, numba.config.NUMBA_NUM_THREADS)
    one, start, scale, mass0, cu0 = _cloud(threads)
    s = one.store
    assert one.counters.merges >= 5 and s.count == 294 - one.counters.merges
    assert (s.flags[: s.count] & COALESCING).any()  # some pairs still growing
    assert np.abs(one.momentum() - start).max() < 1e-10 * scale
    assert float(np.sum(s.mass())) == pytest.approx(mass0, rel=1e-13)
    assert float(np.sum(s.original_diameter[: s.count] ** 3)) == pytest.approx(cu0, rel=1e-13)
    assert int(((s.flags[: s.count] & MERGED) != 0).sum()) >= 1
    two = _cloud(threads)[0]
    assert two.counters.merges == one.counters.merges
    for name in ("position", "velocity", "diameter", "contact_diameter", "flags", "partner", "ident"):
        assert np.array_equal(getattr(two.store, name)[: two.store.count], getattr(s, name)[: s.count]), name


# -- marked partners: no force between them, every other droplet still feels both
_SIZES = (1.0e-3, 0.8e-3, 0.6e-3)  # A, B, C [m]


def _triangle():
    """Centres [m] of A, B, C: A and B overlap by 10 % of their mean diameter, C overlaps each by 5 %."""
    d_a, d_b, d_c = _SIZES
    ab, ac, bc = 0.90 * (d_a + d_b) / 2, 0.95 * (d_a + d_c) / 2, 0.95 * (d_b + d_c) / 2
    x = (ac**2 - bc**2 + ab**2) / (2 * ab)  # C's foot on the A-B line, from A
    centre = np.array([2e-3, 2e-3, 2e-3])
    return centre + np.array([[0.0, 0.0, 0.0], [ab, 0.0, 0.0], [x, math.sqrt(ac**2 - x**2), 0.0]])


def _forces(which, half, marked=False):
    """Contact forces [N] (k, 3) on the droplets ``which`` (indices into A, B, C) placed as in :func:`_triangle`,
    at rest (no dashpot force), from a DemStepper's force pass; A and B marked as partners if ``marked``."""
    store = DropletStore(8)
    store.add(_triangle()[list(which)], np.array(_SIZES)[list(which)], 5000.0)
    if marked:
        store.mark_pairs([0], [1])
    stepper = dem_stepper.DemStepper(store, (0, 0, 0), (6e-3,) * 3, (False, False, False), 1e-5, 5.0, 0.5e-3, 0.5, 0.2e-3,
                             (0, 0, 0), half_list=half, sort_on_rebuild=False)
    stepper.droplets_changed()
    stepper.compute_forces()
    return stepper.force[: store.count].copy()


@pytest.mark.parametrize("half", [True, False], ids=["half_list", "full_list"])
def test_marked_droplets_overlap_without_force_while_a_third_feels_both(half):
    """A and B (1.0 and 0.8 mm) overlap by 10 % and are marked partners; C (0.6 mm) overlaps each by 5 %. Reference:
    the same positions as the separate pairs (A, C), (B, C), (A, B). A feels only C, exactly as in (A, C) alone; B
    only C, as in (B, C); C the sum of both pairs (tolerance: round-off of summing two forces, 1e-12 of the
    largest). Unmarked, the A-B pair pushes with the (A, B) pair's force, so the marking is what removes it."""
    a_c, b_c, a_b = _forces((0, 2), half), _forces((1, 2), half), _forces((0, 1), half)
    # the pair references by hand, k_ref (d_small / d_ref)^2 x overlap with k_ref = 5 N/m at d_ref = 0.5 mm; the
    # force a marking must remove, (A, B)'s, is 4 times (A, C)'s
    for pair, small, overlap in ((a_b, 0.8e-3, 0.10 * 0.9e-3), (a_c, 0.6e-3, 0.05 * 0.8e-3),
                                 (b_c, 0.6e-3, 0.05 * 0.7e-3)):
        assert np.linalg.norm(pair[0]) == pytest.approx(5.0 * (small / 0.5e-3) ** 2 * overlap, rel=1e-12)
    scale = float(np.linalg.norm(a_b[0]))
    marked = _forces((0, 1, 2), half, marked=True)
    np.testing.assert_allclose(marked[0], a_c[0], rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(marked[1], b_c[0], rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(marked[2], a_c[1] + b_c[1], rtol=0, atol=1e-12 * scale)
    free = _forces((0, 1, 2), half)
    np.testing.assert_allclose(free[0], a_c[0] + a_b[0], rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(free[1], b_c[0] + a_b[1], rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(free[2], marked[2], rtol=0, atol=1e-12 * scale)


def _free_flight_run(marked):
    """27 droplets of 0.5 mm, 1.5 mm apart on a lattice, drifting at random up to 5 mm/s with drag, plus two pairs
    (2, 3) overlapping by 10 % and (4, 5) 0.3 mm apart at rest, marked as partners if ``marked``: one 2 ms advance
    of 36 steps with free flight. Returns the stepper."""
    rng = np.random.default_rng(11)
    d = 0.5e-3
    lattice = np.stack(np.meshgrid(*(np.arange(3),) * 3, indexing="ij"), -1).reshape(-1, 3)
    position = 1.5e-3 * (lattice + 1.0)
    position[3] = position[2] + [0.9 * d, 0.0, 0.0]
    position[5] = position[4] + [d + 0.3e-3, 0.0, 0.0]
    velocity = rng.uniform(-5e-3, 5e-3, (27, 3))
    velocity[2:6] = 0.0
    store = DropletStore(64)
    store.add(position, d, 5000.0, velocity=velocity)
    if marked:
        store.mark_pairs([2, 4], [3, 5])
    stepper = dem_stepper.DemStepper(store, (0, 0, 0), (6e-3,) * 3, (False, False, False), 2e-3 / 36, 2.5, d, 0.3, 0.2e-3,
                             (0, 0, 0), sort_on_rebuild=False)
    stepper.droplets_changed()
    beta = np.full(store.capacity, 3 * math.pi * 0.3 * d)  # Stokes drag in a 0.3 Pa s slag [kg/s]
    stepper.set_drag(beta)
    stepper.advance(36, np.zeros((1, 3)), dem_stepper.NO_IMPULSE)
    return stepper


def test_free_flight_never_takes_marked_partners():
    """Free flight (droplets touching nothing skip the sub-steps) must leave marked droplets to the sub-steps: a
    partner pair grows and is drawn together at the event point, which no free-flight budget covers. Unmarked, the
    pair 0.3 mm apart flies free (nothing is near it), so its exclusion when marked is the marking's doing; the pair
    overlapping by 10 % is sub-stepped either way (unmarked it pushes apart; marked it stays at rest, untouched)."""
    plain = _free_flight_run(marked=False)
    free = (plain._free_flags[:27] & records.FREE_FLIGHT) != 0
    assert plain.free_flight_counts.advances == 1
    assert free[4] and free[5] and not free[2] and not free[3]
    stepper = _free_flight_run(marked=True)
    flags = stepper._free_flags[:27]
    assert stepper.free_flight_counts.advances == 1 and stepper.free_flight_counts.breaches == 0
    assert not ((flags & records.FREE_FLIGHT) != 0)[2:6].any()
    assert ((flags & records.FREE_FLIGHT) != 0).sum() == free.sum() - 2  # the other droplets as before
    s = stepper.store
    np.testing.assert_array_equal(s.velocity[2:6], 0.0)  # no force between partners, nothing else near
    np.testing.assert_allclose(s.position[3] - s.position[2], [0.9 * 0.5e-3, 0.0, 0.0], rtol=0, atol=1e-18)
    # the unmarked overlapping pair did push apart
    assert np.linalg.norm(plain.store.position[3] - plain.store.position[2]) > 0.9 * 0.5e-3 * (1 + 1e-6)


# -- the paper's instability (section 4.1), measured: the largest contact force in a collapsing dense cluster
#: Bound on the largest overlap / smaller diameter, in fulldem.max_overlap (the contact model's design point).
OVERLAP_BOUND_FACTOR = 5.0


def _dense_cluster(mode, steps):
    """108 droplets of 1 mm on an fcc lattice with 2 % gaps, collapsing on its centre at 50 /s, in a periodic 20 mm
    box whose pressure gradient carries their weight (every droplet collides within a step or two; all of them
    pair off at once): the largest overlap ratio over ``steps`` fluid steps and the merges."""
    case = load_case("simple", [*SMALL_BOX, "coalescence.size_limit=6e-3", f"coalescence.mode={mode}",
                                "fulldem.overlap_abort=0.9"])
    d, size = 1.0e-3, 0.02
    cell = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    lattice = np.stack(np.meshgrid(*(np.arange(3),) * 3, indexing="ij"), -1).reshape(-1, 1, 3)
    position = (lattice + cell).reshape(-1, 3) * math.sqrt(2) * d * 1.02  # nearest neighbours 1.02 d apart
    position += size / 2 - position.mean(axis=0)
    n = len(position)
    store = DropletStore(256)
    jitter = np.random.default_rng(3).uniform(-2e-6, 2e-6, (n, 3))
    store.add(position + jitter, d, 5100.0, velocity=-50.0 * (position - size / 2))
    weight = n * (5100.0 - 3150.0) * math.pi / 6 * d**3 * 9.80665
    sim = Simulation(case, droplets=store, feed=False, box=((size,) * 3, (0.0, 0.0, 0.0)),
                     periodic=(True, True, True), body_force=(0.0, 0.0, weight / size**3))
    peak = 0.0
    for _ in range(steps):
        peak = max(peak, sim.step()["max_overlap_ratio"])
    return case, peak, sim.counters.merges


def test_delayed_merge_keeps_contacts_within_the_bound_where_the_instantaneous_merge_explodes():
    """The contact stiffness is a numerical choice (fulldem.dem.laws): a contact carrying load_factor = 10 buoyant
    weights of its smaller droplet overlaps max_overlap = 1 % of that droplet's diameter, so the spring force of any
    contact is load_factor x (overlap / d_small) / max_overlap buoyant weights of the smaller droplet (exact, for the
    linear law with k ~ d_small^2). Bound: 5 % overlap, 50 weights, five times the load the stiffness was made for
    (the overlap stays a small fraction of the diameter, where a soft-sphere contact stands for touching droplets;
    a merge itself presses its neighbours by up to (1 - growth_target) d_m / 2, 3 % of a 1 mm droplet here).

    Measured (peak overlap / diameter; 108 droplets): instantaneous merge 0.44 within a step (53 merges: merged
    droplets appear inside their neighbours, the paper's "explosions"); delayed merge 0.033 over 150 steps (54
    merges, steps 47-150), where the first version of the delayed merge, which drew partners together by a fraction
    of what was left and merged them wherever they were, reached 0.128 (256 droplets: 0.25)."""
    case, instantaneous, merged_at_once = _dense_cluster("instantaneous", 3)
    _, delayed, merged_later = _dense_cluster("delayed", 150)
    bound = OVERLAP_BOUND_FACTOR * case.fulldem.max_overlap
    weights = case.fulldem.load_factor * bound / case.fulldem.max_overlap
    assert weights == pytest.approx(50.0)  # the force at the bound, in buoyant weights of the smaller droplet
    assert merged_at_once >= 40 and merged_later >= 40  # both merged most of the 54 pairs
    assert delayed <= bound < instantaneous


def test_the_feed_places_no_droplet_inside_a_marked_partners_grown_contact():
    """A marked partner's contact diameter grows towards the merged droplet's; the feed must keep fed droplets out of
    it, not only out of its plain diameter (placed against the plain one, a fed droplet started up to a quarter of a
    diameter deep in a grown partner, which stopped cubic at 111.9 s on a runaway overlap). Geometry, exact: every
    fed centre lies at least (d_contact + d_new) / 2 from every droplet present."""
    case = load_case("simple", [*SMALL_BOX, "geometry.inlet_diameter=0.006", "fulldem.insertion_layer=0.002",
                                f"geometry.inlet_center=[{BOX / 2},{BOX / 2}]"])
    store = DropletStore(4096)
    sim0 = Simulation(case, droplets=store, feed=False, box=((BOX,) * 3, (0.0, 0.0, 0.0)))
    inlet = sim0.bounds.inlet
    cx, cy = inlet.centre
    z = inlet.top - 1.0e-3
    # a marked pair of 0.3 mm droplets in the middle of the insertion layer, contacts grown to 1.2 mm (far beyond
    # the 0.36 mm such a pair grows to: a geometry test, the annulus between the two diameters made wide)
    store.add([[cx, cy, z], [cx + 0.3e-3, cy, z]], [0.3e-3, 0.3e-3], 5100.0)
    sim = Simulation(case, droplets=store, feed=False, box=((BOX,) * 3, (0.0, 0.0, 0.0)))
    sim.store.mark_pairs([0], [1], time=0.0)
    sim.store.set_contact_diameters([0, 1], np.full(2, 1.2e-3))
    placed = sim.insert(np.full(150, 0.3e-3))
    s = sim.store
    assert placed > 100  # the inlet disk (3 mm radius, 2 mm layer) has room beside the pair
    new = np.arange(2, s.count)
    for old in (0, 1):
        gap = np.linalg.norm(s.position[new] - s.position[old], axis=1) - 0.5 * (s.contact_diameter[old]
                                                                                   + s.diameter[new])
        assert gap.min() >= 0.0  # fails against the plain diameters (checked 2026-12-05: default seed and one other)
