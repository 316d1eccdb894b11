"""Free flight in the DEM stepper (fulldem.dem, *Free flight*): droplets that touch nothing skip the sub-steps and
move in one exact step. The reference is the same stepper with ``free_flight=False`` (every droplet sub-stepped),
plus the analytic solution of drag and a constant force; tolerances are round-off (the exact one-step factors over
T against the product of 36 sub-steps' factors).
"""

import math

import numpy as np
import pytest

from fulldem.dem import integrators
from fulldem.dem import stepper as dem_stepper
from fulldem.droplets import DropletStore


RHO = 5100.0
MU = 0.45
H = 2e-5
STEPS = 36
BODY = (0.0, 0.0, -3.75)  # buoyant weight per mass of matte in slag [m/s^2]


def _stepper(store, free_flight, box=0.02, periodic=(False, False, False), skin=0.1e-3, body=BODY, **kw):
    stepper = dem_stepper.DemStepper(store, (0.0, 0.0, 0.0), (box,) * 3, periodic, H, 5.0, 0.5e-3, 0.5, skin, body,
                             sort_on_rebuild=False, free_flight=free_flight, **kw)
    stepper.droplets_changed()
    stepper.set_drag(3 * math.pi * MU * store.diameter[: store.capacity])
    return stepper


def _store(position, diameter, velocity):
    store = DropletStore(len(diameter))
    store.add(np.asarray(position, dtype=float), np.asarray(diameter, dtype=float), RHO,
              velocity=np.asarray(velocity, dtype=float))
    return store


def _dilute(seed=1, n=300, box=0.02):
    """Droplets 0.4-0.6 mm at least 2 mm apart in a 20 mm box (none touches anything within a fluid step)."""
    rng = np.random.default_rng(seed)
    side = math.ceil(n ** (1 / 3))
    grid = np.stack(np.meshgrid(*(np.arange(side),) * 3, indexing="ij"), -1).reshape(-1, 3)[:n]
    position = (grid + 0.5) * (box / side) + rng.uniform(-0.2e-3, 0.2e-3, (n, 3))
    return position, rng.uniform(0.4e-3, 0.6e-3, n), rng.normal(0.0, 2e-3, (n, 3)), rng.normal(0.0, 2e-3, (n, 3))


def _run(position, diameter, velocity, fluid, free_flight, advances=1, steps=STEPS, **kw):
    store = _store(position, diameter, velocity)
    stepper = _stepper(store, free_flight, **kw)
    n = store.count
    impulse = np.zeros((n, 3))
    for _ in range(advances):
        stepper.advance(steps, fluid, impulse)
    return store, stepper, impulse


def test_dilute_cloud_matches_the_sub_steps_and_the_analytic_solution():
    position, diameter, velocity, fluid = _dilute()
    free, stepper, impulse_free = _run(position, diameter, velocity, fluid, True)
    stepped, _, impulse_stepped = _run(position, diameter, velocity, fluid, False)
    n = free.count
    assert stepper.last_free_fraction == 1.0 and stepper.free_flight_counts.advances == 1
    # round-off: 1e-12 of the box for positions, of the largest speed and momentum for velocities and impulses
    mass = stepper.mass[:n, None]
    np.testing.assert_allclose(free.position[:n], stepped.position[:n], rtol=0, atol=1e-12 * 0.02)
    v_scale = np.abs(stepped.velocity[:n]).max()
    np.testing.assert_allclose(free.velocity[:n], stepped.velocity[:n], rtol=0, atol=1e-12 * v_scale)
    np.testing.assert_allclose(impulse_free, impulse_stepped, rtol=0, atol=1e-12 * (mass * v_scale).max())
    # against the analytic solution of dv/dt = a + (u - v)/tau, written here independently
    tau = mass / (3 * math.pi * MU * diameter[:, None])
    t = STEPS * H
    a = np.array(BODY)
    terminal = fluid + a * tau
    decay = -np.expm1(-t / tau)  # 1 - e^{-t/tau}
    x = position + terminal * t + (velocity - terminal) * tau * decay
    v = terminal + (velocity - terminal) * (1 - decay)
    np.testing.assert_allclose(free.position[:n], x, rtol=0, atol=1e-12 * 0.02)
    np.testing.assert_allclose(free.velocity[:n], v, rtol=0, atol=1e-11 * v_scale)
    # drag impulse beta int (u - v) dt = m (v(t) - v0) - m a t
    np.testing.assert_allclose(impulse_free, mass * (v - velocity) - mass * a * t, rtol=0,
                               atol=1e-11 * (mass * v_scale).max())


def test_colliding_pair_next_to_a_free_droplet_is_unchanged():
    d = 0.5e-3
    # a head-on pair 4 um apart, carried together at 20 mm/s by the slag (they collide within the advance), and a
    # third droplet 0.3 mm away
    position = [[0.01 - 0.5 * d - 2e-6, 0.01, 0.01], [0.01 + 0.5 * d + 2e-6, 0.01, 0.01],
                [0.01, 0.01 + d + 0.3e-3, 0.01]]
    velocity = [[0.01, 0.0, 0.0], [-0.01, 0.0, 0.0], [0.0, 0.0, 1e-3]]
    fluid = np.array(velocity)
    runs = [_run(position, [d, d, d], velocity, fluid, flag, skin=0.5e-3) for flag in (True, False)]
    (free, stepper, impulse_free), (stepped, _, impulse_stepped) = runs
    assert stepper.last_free_fraction == pytest.approx(1 / 3)
    assert stepper.peak_overlap_ratio > 0.0  # the pair did collide
    # the pair's sub-steps are the same operations either way: bit for bit
    np.testing.assert_array_equal(free.position[:2], stepped.position[:2])
    np.testing.assert_array_equal(free.velocity[:2], stepped.velocity[:2])
    np.testing.assert_array_equal(impulse_free[:2], impulse_stepped[:2])
    np.testing.assert_allclose(free.position[2], stepped.position[2], rtol=0, atol=1e-12 * 0.02)
    np.testing.assert_allclose(free.velocity[2], stepped.velocity[2], rtol=0, atol=1e-15)


def test_droplet_heading_for_a_wall_is_sub_stepped():
    d = 0.5e-3
    # droplet 0 is 5 um from the x- wall and moving into it at 20 mm/s; droplet 1 floats in the middle
    position = [[0.5 * d + 5e-6, 0.01, 0.01], [0.01, 0.01, 0.01]]
    velocity = [[-0.02, 0.0, 0.0], [0.0, 0.0, 0.0]]
    fluid = np.array([[-0.02, 0.0, 0.0], [0.0, 0.0, 0.0]])
    runs = [_run(position, [d, d], velocity, fluid, flag) for flag in (True, False)]
    (free, stepper, impulse_free), (stepped, _, impulse_stepped) = runs
    assert stepper.last_free_fraction == 0.5
    assert stepper.peak_overlap_ratio > 0.0  # it did hit the wall
    np.testing.assert_array_equal(free.position[0], stepped.position[0])
    np.testing.assert_array_equal(free.velocity[0], stepped.velocity[0])
    np.testing.assert_array_equal(impulse_free[0], impulse_stepped[0])
    # ... and the same droplet a wall's width further in is free
    position[0][0] += 0.2e-3
    _, stepper, _ = _run(position, [d, d], velocity, fluid, True)
    assert stepper.last_free_fraction == 1.0


def _cluster_in_cloud(seed=3, cloud=216):
    """A dense cluster of 64 touching droplets (overlaps of about 2 % d, random velocities) in a dilute cloud of
    ``cloud`` (less those within 2.5 mm of the cluster)."""
    rng = np.random.default_rng(seed)
    position, diameter, velocity, fluid = _dilute(seed, n=cloud)
    side = 4
    grid = np.stack(np.meshgrid(*(np.arange(side),) * 3, indexing="ij"), -1).reshape(-1, 3)
    cluster = 0.0081 + grid * 0.49e-3 + rng.normal(0, 0.005e-3, grid.shape)
    away = np.linalg.norm(position - 0.0088, axis=1) > 2.5e-3
    position = np.concatenate([cluster, position[away]])
    diameter = np.concatenate([np.full(len(cluster), 0.5e-3), diameter[away]])
    velocity = np.concatenate([rng.normal(0, 5e-3, grid.shape), velocity[away]])
    fluid = np.concatenate([np.zeros(grid.shape), fluid[away]])
    return position, diameter, velocity, fluid


def test_dense_cluster_conserves_momentum_as_before():
    position, diameter, velocity, fluid = _cluster_in_cloud()
    results = []
    for flag in (True, False):
        store = _store(position, diameter, velocity)
        stepper = _stepper(store, flag, periodic=(True, True, True), body=(0.0, 0.0, 0.0))
        n = store.count
        mass = stepper.mass[:n, None]
        for _ in range(5):
            v0 = store.velocity[:n].copy()
            impulse = np.zeros((n, 3))
            stepper.advance(STEPS, fluid, impulse)
            # a closed periodic set without body force: what the droplets gained is what the drag gave them
            gained = (mass * (store.velocity[:n] - v0)).sum(axis=0)
            scale = (mass * np.abs(v0)).sum()
            assert np.abs(gained - impulse.sum(axis=0)).max() < 1e-13 * scale
        results.append((store.position[:n].copy(), store.velocity[:n].copy(), stepper))
    (x_free, v_free, stepper), (x_stepped, v_stepped, _) = results
    counts = stepper.free_flight_counts
    assert counts.advances == 5 and counts.breaches == 0
    assert 0.5 < counts.droplets / (5 * len(diameter)) < 1.0  # the cloud flies free, the cluster sub-steps
    assert stepper.max_overlap_ratio > 0.0
    # the cluster is chaotic but five fluid steps keep the two runs within round-off growth
    np.testing.assert_allclose(x_free, x_stepped, rtol=0, atol=1e-10 * 0.02)
    np.testing.assert_allclose(v_free, v_stepped, rtol=0, atol=1e-8 * np.abs(v_stepped).max())


def test_a_breach_redoes_the_advance_with_every_droplet_sub_stepped(monkeypatch):
    position, diameter, velocity, fluid = _cluster_in_cloud()
    # a negative margin: every sub-stepped droplet in contact leaves its budget, so the advance must be redone
    monkeypatch.setattr(dem_stepper, "FREE_FLIGHT_MARGIN", -0.01)
    free, stepper, impulse_free = _run(position, diameter, velocity, fluid, True, periodic=(True, True, True))
    stepped, _, impulse_stepped = _run(position, diameter, velocity, fluid, False, periodic=(True, True, True))
    counts = stepper.free_flight_counts
    assert counts.breaches == 1 and counts.breach_droplets > 0 and counts.advances == 0
    n = free.count
    np.testing.assert_array_equal(free.position[:n], stepped.position[:n])
    np.testing.assert_array_equal(free.velocity[:n], stepped.velocity[:n])
    np.testing.assert_array_equal(impulse_free, impulse_stepped)
    assert stepper.steps == STEPS


def test_a_list_check_inside_the_advance_redoes_it(monkeypatch):
    """A list check falling inside a free-flight advance (simulated: the compiled step loop stops once after ten
    steps reporting a travel bound over skin/2) undoes the advance, which is redone with every droplet sub-stepped:
    the result is that of the sub-steps bit for bit."""
    position, diameter, velocity, fluid = _cluster_in_cloud()
    real = integrators.step_half_many
    calls = []

    def stop_once(steps, travel_bound, half_skin, *rest):
        calls.append(steps)
        if len(calls) > 1:
            return real(steps, travel_bound, half_skin, *rest)
        taken, peak, worst, _, pending = real(10, travel_bound, half_skin, *rest)
        return taken, peak, worst, 2.0 * half_skin, pending

    monkeypatch.setattr(dem_stepper, "step_half_many", stop_once)
    free, stepper, impulse_free = _run(position, diameter, velocity, fluid, True, periodic=(True, True, True))
    monkeypatch.setattr(dem_stepper, "step_half_many", real)
    stepped, _, impulse_stepped = _run(position, diameter, velocity, fluid, False, periodic=(True, True, True))
    counts = stepper.free_flight_counts
    assert counts.list_checks == 1 and counts.advances == 0 and calls[0] == STEPS
    n = free.count
    np.testing.assert_array_equal(free.position[:n], stepped.position[:n])
    np.testing.assert_array_equal(free.velocity[:n], stepped.velocity[:n])
    np.testing.assert_array_equal(impulse_free, impulse_stepped)
    assert stepper.steps == STEPS


def test_a_droplet_that_outruns_the_skin_turns_free_flight_off():
    """A droplet crossing half the skin within an advance (0.5 m/s over 0.72 ms against a 0.1 mm skin) forces a
    list check inside it: the free-flight advance is undone and sub-stepped (bit for bit the sub-steps' result),
    and the next advance, expecting the same, is sub-stepped from the start."""
    position, diameter, velocity, fluid = _dilute(seed=4, n=64)
    velocity[0] = fluid[0] = (0.5, 0.0, 0.0)
    position[0] = (0.004, 0.0035, 0.0035)
    free, stepper, impulse_free = _run(position, diameter, velocity, fluid, True)
    stepped, other, impulse_stepped = _run(position, diameter, velocity, fluid, False)
    counts = stepper.free_flight_counts
    assert counts.list_checks == 1 and counts.advances == 0
    assert other.neighbours.builds == stepper.neighbours.builds > 1
    np.testing.assert_array_equal(free.position[:64], stepped.position[:64])
    np.testing.assert_array_equal(impulse_free, impulse_stepped)
    stepper.advance(STEPS, fluid, impulse_free)
    assert counts.declined == 1 and counts.list_checks == 1 and counts.advances == 0


def test_settling_bed_has_no_breach():
    """Realistic: 1 000 droplets settle under their buoyant weight through slag onto the floor of a 6 mm box, 40
    fluid steps of 36 sub-steps: a bed forms (contacts) under a dilute cloud (free flight); no budget is breached."""
    rng = np.random.default_rng(8)
    n = 1000
    box = 0.006
    position = rng.uniform(0.3e-3, box - 0.3e-3, (n, 3))
    position[:, 2] *= 0.3  # crowded near the floor
    diameter = rng.uniform(0.35e-3, 0.65e-3, n)
    keep = np.ones(n, dtype=bool)
    for i in range(n):  # drop overlapping ones
        if keep[i]:
            gap = np.linalg.norm(position[i + 1:] - position[i], axis=1) - 0.5 * (diameter[i + 1:] + diameter[i])
            keep[i + 1:] &= gap > 1e-6
    position, diameter = position[keep], diameter[keep]
    store = _store(position, diameter, np.zeros_like(position))
    stepper = _stepper(store, True, box=box, skin=0.15e-3)
    fluid = np.zeros((1, 3))
    impulse = np.zeros((store.count, 3))
    for _ in range(40):
        stepper.advance(STEPS, fluid, impulse)
    counts = stepper.free_flight_counts
    assert stepper.peak_overlap_ratio > 0.0 or stepper.max_overlap_ratio > 0.0
    assert counts.breaches == 0
    assert counts.advances >= 30
    assert 0.2 < counts.droplets / (counts.advances * store.count) < 1.0


def test_gathered_sub_steps_are_the_sub_steps_in_place_bit_for_bit():
    """The sub-stepped droplets of a free-flight advance are stepped in arrays of their own (fulldem.dem.gather): the
    same operations in the same order as stepping them in place among the free droplets (``gather_free=False``),
    so positions, velocities, forces, drag impulses, the contact record and the free-flight deviations agree bit for
    bit -- with several slabs, periodic images, a marked coalescing pair inside the cluster (its mutual partner is
    found through the gathered indices) and per-droplet fluid velocities."""
    position, diameter, velocity, fluid = _cluster_in_cloud(cloud=2000)
    runs = []
    for gather in (True, False):
        store = _store(position, diameter, velocity)
        store.mark_pairs([0, 5], [1, 6])  # touching neighbours in the cluster (grid steps along z)
        store.set_contact_diameters([0, 1, 5, 6], np.full(4, 0.52e-3))
        stepper = dem_stepper.DemStepper(store, (0.0, 0.0, 0.0), (0.02,) * 3, (True, True, True), H, 5.0, 0.5e-3, 0.5,
                                         0.1e-3, BODY, free_flight=True, record_first_contacts=True,
                                         every_contact=True)
        stepper.gather_free = gather
        stepper.droplets_changed()
        stepper.set_drag(3 * math.pi * MU * store.diameter[: store.capacity])
        n = store.count
        local_fluid = fluid[store.ident[:n]]  # (the set-up sorted the droplets; later re-sorts permute it in place)
        impulse = np.zeros((n, 3))
        contacts = []
        for _ in range(4):
            stepper.advance(STEPS, local_fluid, impulse)
            contacts.append(stepper.take_first_contacts())
        runs.append((store, stepper, impulse, contacts))
    (gathered, stepper, impulse_gathered, record_gathered), (in_place, other, impulse_in_place, record_in_place) = runs
    n = gathered.count
    counts = stepper.free_flight_counts
    assert counts.advances == 4 and counts.breaches == 0 and 0.0 < stepper.last_free_fraction < 1.0
    assert stepper._gathered.bounds.shape[0] - 1 >= 4  # several slabs, so the slab mapping matters
    assert sum(len(a) for a, _, _ in record_gathered) > 0 and stepper.max_overlap_ratio > 0.0
    np.testing.assert_array_equal(gathered.position[:n], in_place.position[:n])
    np.testing.assert_array_equal(gathered.velocity[:n], in_place.velocity[:n])
    np.testing.assert_array_equal(stepper.force[:n], other.force[:n])
    np.testing.assert_array_equal(impulse_gathered, impulse_in_place)
    np.testing.assert_array_equal(stepper._deviation[:n], other._deviation[:n])
    for (a, b, speed), (a2, b2, speed2) in zip(record_gathered, record_in_place):
        np.testing.assert_array_equal(a, a2)
        np.testing.assert_array_equal(b, b2)
        np.testing.assert_array_equal(speed, speed2)


def test_an_advance_the_list_cannot_last_runs_as_free_flight_segments():
    """A droplet carried at 80 mm/s travels 58 um over a 0.72 ms advance, more than half the 0.1 mm skin: the first
    advance's free flight is undone by the list check inside it; the next, expecting the same travel, runs as two
    free-flight advances of half the steps with a list check between them (FREE_FLIGHT_SEGMENT_FILL) instead of
    sub-stepping every droplet; the result is the sub-steps' to round-off, as for any free flight."""
    position, diameter, velocity, fluid = _dilute(seed=4, n=64)
    velocity[0] = fluid[0] = (0.08, 0.0, 0.0)
    position[0] = (0.004, 0.0035, 0.0035)
    free, stepper, impulse_free = _run(position, diameter, velocity, fluid, True, advances=2)
    stepped, _, impulse_stepped = _run(position, diameter, velocity, fluid, False, advances=2)
    counts = stepper.free_flight_counts
    assert counts.list_checks == 1 and counts.declined == 0 and counts.advances == 2
    assert stepper.last_free_fraction == 1.0 and stepper.steps == 2 * STEPS
    n = free.count
    np.testing.assert_allclose(free.position[:n], stepped.position[:n], rtol=0, atol=1e-12 * 0.02)
    v_scale = np.abs(stepped.velocity[:n]).max()
    np.testing.assert_allclose(free.velocity[:n], stepped.velocity[:n], rtol=0, atol=1e-12 * v_scale)
    mass = stepper.mass[:n, None]
    np.testing.assert_allclose(impulse_free, impulse_stepped, rtol=0, atol=1e-12 * (mass * v_scale).max())
