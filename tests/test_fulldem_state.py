"""One owner of the droplet state (fulldem.droplets.DropletStore): every field is moved, reordered and checkpointed
from one field list, changes are seen by version, and the droplet set cannot change between a step's deposits."""

import numpy as np
import pytest

import fulldem.droplets as fdrop
from fulldem.driver import checkpoint_state, restore_state
from fulldem.io.checkpoint import load_checkpoint, save_checkpoint
from fulldem.stepper import Simulation
from settler.cases import load_case


SMALL = ["fulldem.cell_size=0.01", "fulldem.snapshot_interval=0"]


def test_a_new_field_is_stored_moved_and_checkpointed_with_no_other_edit(tmp_path, monkeypatch):
    """Add a per-droplet field to FIELDS (as a coalescence growth target would be): it survives removal, reordering
    and a checkpoint written to disk and restored into a new simulation."""
    monkeypatch.setitem(fdrop.FIELDS, "growth_target", (None, np.float64))
    case = load_case("demo", SMALL)
    sim = Simulation(case)
    for _ in range(5):
        sim.step()
    s, n = sim.store, sim.store.count
    assert n > 10 and s.growth_target.shape == (s.capacity,)
    s.growth_target[:n] = s.ident[:n] * 1e-3  # a value tied to each droplet's identity
    s.remove(np.arange(n) % 3 == 0)
    s.reorder(np.arange(s.count)[::-1].copy())
    n = s.count
    np.testing.assert_array_equal(s.growth_target[:n], s.ident[:n] * 1e-3)
    arrays, meta = checkpoint_state(sim)
    save_checkpoint(tmp_path / "c.npz", arrays, meta)
    back = Simulation(case)
    restore_state(back, *load_checkpoint(tmp_path / "c.npz"))
    assert back.store.count == n
    for name in fdrop.FIELDS:
        np.testing.assert_array_equal(getattr(back.store, name)[:n], getattr(s, name)[:n], err_msg=name)


def test_every_change_moves_the_version_and_the_dem_sees_it():
    store = fdrop.DropletStore(4)
    seen = [store.version]
    store.add(np.random.default_rng(1).uniform(0.01, 0.09, (6, 3)), 1e-3, 5000.0)
    seen.append(store.version)  # add (and the growth it needed)
    store.reorder(np.array([5, 4, 3, 2, 1, 0]))
    seen.append(store.version)
    store.remove(np.array([True, False, False, False, False, False]))
    seen.append(store.version)
    store.remove(np.zeros(5, dtype=bool))  # removes nothing: no change
    seen.append(store.version)
    assert seen[0] < seen[1] < seen[2] < seen[3] == seen[4]

    sim = Simulation(load_case("demo", SMALL))
    sim.step()
    assert sim.dem.ready  # set up in the first step, the feed's droplets included
    sim.store.reorder(np.arange(sim.store.count)[::-1].copy())
    assert not sim.dem.ready
    sim.step()
    assert sim.dem.ready


def test_the_droplet_set_cannot_change_between_a_steps_deposits(monkeypatch):
    """The coupling deposits volume at x^n and the owed drag at the same droplets' start rows: a change of the set in
    between (a merge inside the DEM sub-steps, say) is refused, not silently mis-deposited."""
    sim = Simulation(load_case("demo", SMALL))
    sim.step()
    advance = sim.dem.advance

    def advance_then_reorder(*args, **kwargs):
        out = advance(*args, **kwargs)
        sim.store.reorder(np.arange(sim.store.count)[::-1].copy())
        return out

    monkeypatch.setattr(sim.dem, "advance", advance_then_reorder)
    with pytest.raises(RuntimeError, match="between the step's deposits"):
        sim.step()


def _periodic_cloud(n=150, seed=4):
    """The momentum test's set-up (tests/test_fulldem_stepper.py): droplets in a periodic box whose mean pressure
    gradient carries their buoyant weight, so the total momentum stays constant while they settle."""
    import math

    from fulldem.droplets import DropletStore

    case = load_case("simple", ["feed.mass_rate=0", "coalescence.enabled=false", "fulldem.cell_size=0.005",
                                "fulldem.fluid_step=0.002"])
    rng = np.random.default_rng(seed)
    size, d = 0.05, 1.2e-3
    store = DropletStore(256)
    store.add(rng.uniform(0.1 * size, 0.9 * size, (n, 3)), rng.uniform(0.8, 1.2, n) * d, 5100.0,
              age=rng.uniform(0.0, 5.0, n))
    weight = np.sum((5100.0 - 3150.0) * math.pi / 6 * store.diameter[:n] ** 3) * 9.80665
    sim = Simulation(case, droplets=store, feed=False, box=((size,) * 3, (0.0, 0.0, 0.0)),
                     periodic=(True, True, True), body_force=(0.0, 0.0, weight / size**3))
    return sim


def test_merges_at_the_event_point_keep_momentum_and_matte():
    """Pairs merged at the end-of-step event point: the total momentum (fluid + droplets + drag owed to the fluid)
    stays constant to round-off as without merges, and the matte mass, Cu2S (original volume) and mass x age of the
    droplets are those before the merge."""
    sim = _periodic_cloud()
    sim.step()
    start = sim.momentum()
    scale = np.sum(np.abs(sim.impulse[: sim.store.count]))
    s = sim.store

    def books():
        n = s.count
        mass = s.density[:n] * s.diameter[:n] ** 3
        return n, mass.sum(), (s.original_diameter[:n] ** 3).sum(), (mass * s.age[:n]).sum()

    n0, mass0, cu0, age0 = books()
    # the five closest disjoint pairs (nearest neighbours in the box, as the contact loop would find them)
    pos = s.position[:n0]
    dist = np.linalg.norm(pos[:, None] - pos[None], axis=-1) + np.eye(n0)
    used, first, second = set(), [], []
    for flat in np.argsort(dist, axis=None):
        i, j = divmod(int(flat), n0)
        if i < j and i not in used and j not in used:
            first.append(i), second.append(j), used.update((i, j))
        if len(first) == 5:
            break
    sim.propose_merges(second[:2], first[:2])  # proposals may come in several calls and either order
    sim.propose_merges(first[2:], second[2:])
    sim.step()  # merged at this step's end
    n1, mass1, cu1, age1 = books()
    assert n1 == n0 - 5 and sim.counters.merges == 5
    assert mass1 == pytest.approx(mass0, rel=1e-14) and cu1 == pytest.approx(cu0, rel=1e-14)
    assert age1 == pytest.approx(age0, rel=1e-14)  # (ages do not advance without the reaction submodel)
    for _ in range(5):
        sim.step()
    assert np.abs(sim.momentum() - start).max() < 1e-10 * scale


def test_submodels_act_at_the_step_event_points():
    """A submodel's at_start runs before the step's deposits (a droplet it adds takes part in that step) and its
    at_end after the step (at the new time); the built-in ones are the feed, merges and exits, in that order."""
    from fulldem.submodels.base import Exits, Feed, Merges, Submodel

    class Recorder(Submodel):
        name = "recorder"

        def __init__(self):
            self.seen = []

        def at_start(self, sim):
            self.seen.append(("start", sim.time))
            sim.store.add([[0.05, 0.05, 0.05]], 1e-3, 5200.0)

        def at_end(self, sim):
            self.seen.append(("end", sim.time))

    sim = Simulation(load_case("demo", [*SMALL, "coalescence.enabled=false"]), feed=False)
    assert [type(m) for m in sim.submodels] == [Feed, Merges, Exits]
    recorder = Recorder()
    sim.submodels.insert(1, recorder)
    sim.step()
    assert recorder.seen == [("start", 0.0), ("end", pytest.approx(sim.dt))]
    assert sim.store.count == 1 and sim.store.velocity[0, 2] < 0.0  # it settled during the step it was added in



def test_remove_keeps_order_and_partners_by_identity():
    """Removal (a compiled in-place compaction) keeps the survivors in order with every field, re-points each
    partner to the same droplet (by ident), and unmarks a droplet whose partner left, giving back its true size."""
    rng = np.random.default_rng(7)
    n = 2000
    s = fdrop.DropletStore(16)
    s.add(rng.uniform(0.0, 0.1, (n, 3)), rng.uniform(2e-4, 1e-3, n), 5000.0, velocity=rng.normal(size=(n, 3)),
          age=rng.random(n))
    pairs = rng.permutation(n)[:1200].reshape(2, -1)
    s.mark_pairs(pairs[0], pairs[1], 0.25)
    s.contact_diameter[:n] = 1.2 * s.diameter[:n]
    before = {name: getattr(s, name)[:n].copy() for name in fdrop.FIELDS}
    partner_ident = np.where(before["partner"] >= 0, before["ident"][before["partner"]], -1)
    gone = rng.random(n) < 0.3
    s.remove(gone)
    kept = ~gone
    assert s.count == kept.sum()
    for name in ("position", "velocity", "diameter", "age", "ident", "marked_time"):
        np.testing.assert_array_equal(getattr(s, name)[: s.count], before[name][kept], err_msg=name)
    ident = s.ident[: s.count]
    has = s.partner[: s.count] >= 0
    np.testing.assert_array_equal(ident[s.partner[: s.count][has]], partner_ident[kept][has])
    lost = (partner_ident[kept] >= 0) & ~np.isin(partner_ident[kept], ident)
    assert lost.sum() > 50 and not has[lost].any()
    assert not (s.flags[: s.count][lost] & fdrop.COALESCING).any()
    np.testing.assert_array_equal(s.contact_diameter[: s.count][lost], s.diameter[: s.count][lost])
    np.testing.assert_array_equal(s.contact_diameter[: s.count][has], 1.2 * s.diameter[: s.count][has])
    assert (s.partner[s.count: n] == -1).all()
