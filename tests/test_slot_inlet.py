"""A slot inlet (geometry.inlet_length): the feed enters over a rectangle instead of a disk, so that a wide slab can
show how many channels a uniform feed forms (issue 21's wide slab). Checked: the case refuses a slot off the top face
or with a slag feed, the candidates lie uniformly inside the rectangle with every droplet wholly inside it, the
engine feeds the scheduled mass over the slot and conserves it, and popbal refuses a case it does not represent."""

import numpy as np
import pytest

import fulldem
from fulldem.boundaries import Inlet
from fulldem.submodels.feed import draw_slot_candidates
from settler.cases import CaseError, load_case

SLAB = {"geometry.width": 0.1, "geometry.depth": 0.03, "geometry.height": 0.05, "geometry.inlet_length": 0.08,
        "geometry.inlet_diameter": 0.02}


def quiet(*args):
    pass


def test_a_slot_is_a_rectangle_of_length_by_width():
    slot = Inlet((0.2, 0.025), 0.02, 0.1, 0.375)
    assert slot.is_slot and slot.half_extent == (0.1875, 0.02)
    assert slot.area == pytest.approx(0.375 * 0.04, rel=1e-15)
    inside = slot.contains(np.array([0.2, 0.0126, 0.0124, 0.2, 0.2]), np.array([0.025, 0.025, 0.025, 0.0449, 0.0451]))
    assert inside.tolist() == [True, True, False, True, False]
    disk = Inlet((0.0, 0.0), 0.01, 0.1)
    assert not disk.is_slot and disk.half_extent == (0.01, 0.01) and disk.area == pytest.approx(np.pi * 1e-4)
    case = load_case("demo", SLAB)
    assert case.inlet_is_slot and case.inlet_area == pytest.approx(0.08 * 0.02, rel=1e-15)


@pytest.mark.parametrize("overrides, key", [
    ({"geometry.inlet_length": 0.11}, "geometry.inlet_length = 0.11"),
    ({"geometry.inlet_diameter": 0.032}, "geometry.inlet_diameter = 0.032"),
    ({"geometry.inlet_center": [0.02, 0.01]}, r"geometry.inlet_center = \[0.02, 0.01\]"),
])
def test_a_slot_off_the_top_face_is_refused(overrides, key):
    with pytest.raises(CaseError, match=key):
        load_case("demo", {**SLAB, **overrides})


def test_a_slot_takes_no_slag_feed():
    with pytest.raises(CaseError, match="slag.feed_rate"):
        load_case("cubic", {"geometry.inlet_length": 0.15})


def test_candidates_lie_uniformly_inside_the_slot():
    rng = np.random.default_rng(3)
    diameters = np.array([0.5e-3, 2e-3, 4e-3] * 400)
    half = (0.05, 0.006)
    cand = draw_slot_candidates(rng, diameters, (0.1, 0.02), half, 0.05, 1e-3, 20)
    assert cand.shape == (1200, 20, 3)
    for axis in (0, 1):
        offset = np.abs(cand[..., axis] - (0.1, 0.02)[axis])
        allowed = half[axis] - 0.5 * diameters[:, None]
        assert (offset <= allowed + 1e-15).all()
        # uniform on [-L, L]: variance L^2 / 3 per droplet size, 8 000 draws each -> about 1.6 % standard error
        for d in (0.5e-3, 2e-3, 4e-3):
            rows = diameters == d
            length = half[axis] - 0.5 * d
            var = np.mean((cand[rows, :, axis] - (0.1, 0.02)[axis]) ** 2)
            assert var == pytest.approx(length**2 / 3.0, rel=0.06)
    assert (cand[..., 2] <= 0.05 - 0.5 * diameters[:, None]).all()
    assert (cand[..., 2] >= 0.05 - 0.5 * diameters[:, None] - 1e-3).all()


def test_the_engine_feeds_a_slot_and_conserves_matte(tmp_path):
    setup = fulldem.setup("demo", {**SLAB, "feed.mass_rate": 1e-3, "fulldem.cell_size": 0.005,
                                   "fulldem.output_interval": 0.01, "fulldem.snapshot_interval": 0.02,
                                   "fulldem.fluid_step": 0.002})
    result = fulldem.run(setup, out=tmp_path, end_time=0.04, progress=False, log=quiet)
    ts = result.timeseries
    assert (np.abs(ts["mass_balance_error"]) < 1e-12).all()
    # the feed schedule's mass [kg]: rate x time, placed without backlog in an empty slot
    assert ts["mass_fed"].iloc[-1] == pytest.approx(1e-3 * 0.04, rel=0.05)
    drops = result.droplets()
    x, y, d = drops["position"][:, 0], drops["position"][:, 1], drops["diameter"]
    assert len(d) > 50
    assert (np.abs(x - 0.05) <= 0.04 - 0.5 * d + 1e-12).all()
    assert (np.abs(y - 0.015) <= 0.01 - 0.5 * d + 1e-12).all()
    # a slot's length spread: the fed droplets cover it, not only a disk of its width around the centre
    assert np.ptp(x) > 0.06
    # the slab tools read the run's slag snapshots: a count per snapshot at three heights, and the figure
    from analysis.channels import draw, run_counts

    rows = run_counts(tmp_path)
    assert [r["time"] for r in rows] == pytest.approx([0.0, 0.02, 0.04])
    assert all(set(r) == {"time", "n_25", "n_50", "n_75", "centres_50", "droplet_channels", "extents"} for r in rows)
    assert rows[0]["n_50"] == 0 and rows[0]["droplet_channels"] == 0  # slag at rest, no droplet: no channel
    draw(tmp_path, tmp_path / "channels.png")
    assert (tmp_path / "channels.png").stat().st_size > 10_000


def test_popbal_refuses_a_slot():
    from popbal.model import build

    with pytest.raises(CaseError, match="geometry.inlet_length = 0.08"):
        build(load_case("demo", SLAB))
