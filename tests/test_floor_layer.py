"""analysis.floor_layer: the matte layer over the floor, by size, as the excess thickness of the droplets' height
profile (the measure behind popbal's bottom layer thickness), against the closed form of an exponential layer."""

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.floor_layer import (BIN, EDGES, excess_thickness, layer_profiles, layer_table, measure_floor_layer,
                                  read_floor_layer, write_floor_layer)
from settler.cases import load_case
from settler.derived import settling_velocity
from tests.test_floor_lift import _run_folder

HEIGHT = 0.1  # the demo's slag height [m]


def _binned(decay):
    """The estimate's closed form for an excess A exp(-z / decay) over 40 bins of BIN: the excess summed over the
    bins over the floor bin's, sum_k (e^-k x - e^-(k+1) x) / (1 - e^-x) with x = BIN / decay, times BIN."""
    x = BIN / decay
    return BIN * (1.0 - math.exp(-40 * x)) / (1.0 - math.exp(-x))


def test_the_excess_thickness_of_an_exponential_layer_is_its_closed_form():
    """Bin means of n_far (1 + A exp(-z / lambda)) over 1 mm bins to 40 mm, lambda = 4 mm: the estimate is
    BIN / (1 - exp(-BIN / lambda)) = 4.52 mm (lambda + BIN / 2 to 1 %), whatever A and n_far; a uniform profile has
    no layer (NaN)."""
    edges = np.arange(41) * BIN
    for amplitude, far in ((10.0, 3.0), (2.0, 50.0)):
        excess = amplitude * far * 4e-3 * (np.exp(-edges[:-1] / 4e-3) - np.exp(-edges[1:] / 4e-3)) / BIN
        # the far span keeps exp(-7.5) = 6e-4 of the floor's excess, which the far value takes in: within 2e-3
        delta = excess_thickness(far + excess, BIN, slice(30, 40))
        assert delta == pytest.approx(_binned(4e-3), rel=2e-3)
        assert delta == pytest.approx(4e-3 + 0.5 * BIN, rel=0.01)
    assert math.isnan(excess_thickness(np.full(40, 7.0), BIN, slice(30, 40)))


def _layer_droplets(rng, count, decay, diameter, height=HEIGHT):
    """``count`` droplets of ``diameter`` whose lowest points lie half in a uniform far field over the lower 0.4 of
    the height and half in an exponential layer of ``decay`` [m] over the floor."""
    uniform = rng.uniform(0.0, 0.4 * height, count // 2)
    layer = rng.exponential(decay, count - count // 2)
    low = np.concatenate([uniform, layer])
    return low + 0.5 * diameter, np.full(count, diameter)


def test_sampled_layers_of_two_sizes_give_each_its_own_thickness():
    """Ten snapshots of 0.5 mm droplets in a 4 mm layer and 1.1 mm droplets in a 2 mm one over a uniform far field:
    each size bin's thickness is its layer's closed form (4.52 and 2.54 mm) within the sampling noise (3 %), the
    other bins hold nothing (NaN), and the mean diameter and settling velocity are the bin's droplets'."""
    rng = np.random.default_rng(11)
    frames = []
    for _ in range(10):
        z_small, d_small = _layer_droplets(rng, 40000, 4e-3, 5e-4)
        z_large, d_large = _layer_droplets(rng, 40000, 2e-3, 1.1e-3)
        frames.append(pd.DataFrame({"z": np.concatenate([z_small, z_large]),
                                    "diameter": np.concatenate([d_small, d_large])}))
    profiles = layer_profiles(frames, HEIGHT)
    case = load_case("demo")
    table, by_volume = layer_table(profiles, case)
    small = table[table.diameter_low == EDGES[1]].iloc[0]
    large = table[table.diameter_low == EDGES[5]].iloc[0]
    assert small.thickness == pytest.approx(_binned(4e-3), rel=0.03)
    assert large.thickness == pytest.approx(_binned(2e-3), rel=0.03)
    assert small.mean_diameter == pytest.approx(5e-4) and large.mean_diameter == pytest.approx(1.1e-3)
    assert small.settling_velocity == pytest.approx(float(settling_velocity(case, 5e-4)), rel=1e-9)
    others = table[~table.diameter_low.isin([EDGES[1], EDGES[5]])]
    assert others.thickness.isna().all() and (others.floor_number == 0).all()
    # by volume the large droplets dominate (10.6 times the volume each), so the layer is nearer their 2.54 mm
    assert _binned(2e-3) < by_volume < _binned(4e-3)


def test_a_run_folders_floor_layer_is_measured_stored_and_read_back(tmp_path):
    """A synthetic demo run folder with three snapshots of a 3 mm layer of 0.6 mm droplets: the window's snapshots
    give the layer's closed form, the file round-trips with its window and thickness."""
    rng = np.random.default_rng(5)
    snapshots = []
    for time in (20.0, 21.0, 22.0):
        z, d = _layer_droplets(rng, 60000, 3e-3, 6e-4)
        n = len(z)
        points = np.column_stack([rng.uniform(0.01, 0.09, n), rng.uniform(0.01, 0.09, n), z])
        data = {"diameter": d, "velocity": np.zeros((n, 3)), "density": np.full(n, 5100.0), "age": np.zeros(n),
                "ident": np.arange(n, dtype=float), "merged": np.zeros(n)}
        snapshots.append((time, points, data))
    folder = tmp_path / "run"
    _run_folder(folder, snapshots)
    table, meta = measure_floor_layer(folder, (20.0, 22.0))
    row = table[table.diameter_low == EDGES[2]].iloc[0]
    assert row.thickness == pytest.approx(_binned(3e-3), rel=0.03)
    assert meta["thickness"] == pytest.approx(row.thickness, rel=1e-9)  # one size: by volume = by number
    assert meta["snapshots"] == [20.0, 21.0, 22.0]
    path = write_floor_layer(folder, tmp_path, (20.0, 22.0))
    again, read = read_floor_layer(path)
    assert again["thickness"].to_numpy() == pytest.approx(table["thickness"].to_numpy(), nan_ok=True, rel=1e-6)
    assert read["window"] == (20.0, 22.0) and read["thickness"] == pytest.approx(meta["thickness"], rel=1e-6)


#: The stored reference runs (the set made at a04ea13, data/reference/README.md).
REMADE = Path(__file__).parents[1] / "data" / "reference"
DEMO_CASE = REMADE / "demo_cell_25/case.toml"


def _stored_layer(folder, thickness, case_file=DEMO_CASE):
    """A stored run stand-in: the demo's case.toml and a floor_layer.csv whose header holds ``thickness`` [m]."""
    from analysis.files import window_header
    from analysis.floor_layer import FLOOR_LAYER_FILE, FLOOR_LAYER_UNITS
    from settler.output import units_line

    folder.mkdir()
    (folder / "case.toml").write_text(Path(case_file).read_text())
    table = pd.DataFrame({column: [1.0] for column in FLOOR_LAYER_UNITS})
    header = units_line(FLOOR_LAYER_UNITS) + window_header((45.0, 60.0), [60.0], {"thickness": f"{thickness!r} m"})
    (folder / FLOOR_LAYER_FILE).write_text(header + table.to_csv(index=False))


def test_bottom_factor_is_the_geometric_mean_of_the_floor_layers_over_the_channel_radius(tmp_path):
    """popbal's bottom layer factor measured: delta_b / R_c per run. With the inlet form R_c = k x the inlet radius
    (k = 0.5, the demo's 37.5 mm: 18.75 mm), layers of 3.75 and 7.5 mm give factors 0.2 and 0.4, their geometric
    mean sqrt(0.08), log standard deviation ln 2 / sqrt 2 (spread x1.63), standard error mean x that / sqrt 2; a run
    with no layer (NaN) is named and left out."""
    from analysis.floor_layer import FLOOR_LAYER_FILE, bottom_factor

    _stored_layer(tmp_path / "a", 3.75e-3)
    _stored_layer(tmp_path / "b", 7.5e-3)
    values = {"popbal.channel_radius_form": "inlet", "popbal.channel_radius_factor": 0.5}
    got = bottom_factor(["a", "b"], tmp_path, values)
    sd = math.log(2.0) / math.sqrt(2.0)
    assert got["per_run"]["a"]["channel_radius"] == pytest.approx(0.01875, rel=1e-12)
    assert [got["per_run"][r]["factor"] for r in "ab"] == pytest.approx([0.2, 0.4], rel=1e-12)
    assert got["value"] == pytest.approx(math.sqrt(0.08), rel=1e-12)
    assert got["spread"] == pytest.approx(math.exp(sd), rel=1e-12)
    assert got["standard_error"] == pytest.approx(math.sqrt(0.08) * sd / math.sqrt(2.0), rel=1e-12)
    with pytest.raises(ValueError, match="none was given"):
        bottom_factor([], tmp_path, values)
    _stored_layer(tmp_path / "c", float("nan"))  # a floor without a layer (the deep family's) is left out, named
    without = bottom_factor(["a", "c", "b"], tmp_path, values)
    assert without["value"] == got["value"] and without["no_layer"] == ["c"] and without["runs"] == ["a", "b"]
    with pytest.raises(ValueError, match="no floor layer in c"):
        bottom_factor(["c"], tmp_path, values)
    (tmp_path / "c" / FLOOR_LAYER_FILE).unlink()
    with pytest.raises(ValueError, match=r"c/floor_layer.csv: missing"):
        bottom_factor(["c"], tmp_path, values)
