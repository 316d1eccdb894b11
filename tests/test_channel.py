"""The channel measures both engines write (settler.output.TIME_SERIES: channel_radius, channel_velocity; and
channel_profile.csv), against closed forms: the volume-weighted median distance, an exact interpolation of a linear
field, a ring of droplets, and a uniform suspension in popbal's two zones."""

import math

import numpy as np
import pytest

from settler.cases import load_case
from settler.output import CHANNEL_PROFILE, PROFILE_BANDS, half_volume_radius


def test_half_volume_radius_is_the_volume_weighted_median():
    # volumes 1 and 3 at 1 m and 2 m: half the volume (2) lies between the droplets' half-volume points 0.5 and 2.5
    assert half_volume_radius([2.0, 1.0], [3.0, 1.0]) == pytest.approx(1.75, rel=1e-15)
    assert half_volume_radius([0.3], [1e-9]) == 0.3
    assert math.isnan(half_volume_radius([], []))
    # equal droplets on many equal-area rings of a disk of radius R: R / sqrt(2) (to the ring spacing)
    rings = (np.arange(2000) + 0.5) / 2000
    assert half_volume_radius(np.sqrt(rings) * 0.1, np.ones(2000)) == pytest.approx(0.1 / math.sqrt(2), rel=1e-3)


def test_face_interpolation_is_exact_for_a_linear_field():
    from fulldem.fluid.grid import Grid
    from fulldem.io.channel import face_value

    grid = Grid((6, 5, 8), 0.01, (0.1, 0.0, -0.02))
    shape = grid.face_shape(2)
    i, j, k = np.meshgrid(*(np.arange(n) for n in shape), indexing="ij")
    x = grid.lower[0] + (i + 0.5) * grid.spacing  # z-faces: cell centres in x and y, faces in z
    y = grid.lower[1] + (j + 0.5) * grid.spacing
    z = grid.lower[2] + k * grid.spacing
    w = 0.3 + 2.0 * x - 1.5 * y + 4.0 * z
    for point in [(0.131, 0.027, 0.013), (0.145, 0.0449, 0.0551), (0.1151, 0.0051, -0.02)]:
        expected = 0.3 + 2.0 * point[0] - 1.5 * point[1] + 4.0 * point[2]
        assert face_value(grid, w, 2, point) == pytest.approx(expected, rel=1e-12)


def test_fulldem_channel_radius_of_a_ring_and_the_profile():
    """Droplets on a ring of radius 12 mm around the inlet axis at mid-height: channel_radius is 12 mm; the slag at
    rest has no velocity on the axis; the profile has one row per band, the ring's volume in the middle ones."""
    from fulldem.droplets import DropletStore
    from fulldem.io import channel
    from fulldem.stepper import Simulation

    case = load_case("demo", ["feed.mass_rate=0"])
    height = case.geometry.height
    x0, y0 = case.inlet_center
    angles = np.linspace(0.0, 2 * math.pi, 24, endpoint=False)
    store = DropletStore(64)
    store.add(np.column_stack([x0 + 0.012 * np.cos(angles), y0 + 0.012 * np.sin(angles),
                               np.full(24, 0.5 * height + 1e-3)]), 1e-3, 5100.0)
    sim = Simulation(case, droplets=store, feed=False)
    columns = channel.time_series_columns(sim)
    assert columns["channel_radius"] == pytest.approx(0.012, rel=1e-12)
    assert columns["channel_velocity"] == 0.0
    rows = channel.profile_rows(sim)
    assert len(rows) == PROFILE_BANDS and set(rows[0]) == set(CHANNEL_PROFILE)
    volume = 24 * math.pi / 6 * 1e-9
    assert sum(r["droplet_volume"] for r in rows) == pytest.approx(volume, rel=1e-12)
    assert sum(not math.isnan(r["channel_radius"]) for r in rows) == 1


def test_popbal_channel_radius_of_a_uniform_suspension():
    """The same number density of one size in both zones: the volume is spread evenly over the cross-section, so
    the half-volume radius is that of half the area, R_out / sqrt(2) with R_out = sqrt(A / pi)."""
    from popbal.driver import _channel, _Work
    from popbal.kernels import NUMBER, QUANTITIES
    from popbal.model import ZONES, setup

    model = setup(load_case("demo"))
    cells, sections = model.cells, model.grid.size
    content = np.zeros((len(ZONES), cells, QUANTITIES, sections))
    content[:, :, NUMBER, 3] = 1e6  # the demo has no roof or bottom layer (zone area 0)
    work = _Work(cells, sections)
    work.diameters[:] = 1e-3
    radius, velocity, volume = _channel(model, content, work, np.arange(cells))
    area = float(model.zone_area.sum())
    assert radius == pytest.approx(math.sqrt(area / math.pi) / math.sqrt(2), rel=1e-12)
    assert volume == pytest.approx(1e6 * math.pi / 6 * 1e-9 * area * model.cell_height * cells, rel=1e-12)
