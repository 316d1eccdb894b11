"""The strict reader of initial-droplet lists (fulldem.io.droplet_list)."""

import time

import numpy as np
import pytest

from fulldem.io.droplet_list import COLUMNS, DropletListError, read_droplet_list


LOWER, UPPER = (0.0, 0.0, 0.0), (0.05, 0.04, 0.1)
SLAG = 3300.0
MATTE = 5200.0


def read(path, **kw):
    args = dict(lower=LOWER, upper=UPPER, slag_density=SLAG, default_density=MATTE, overlap_limit=0.01)
    args.update(kw)
    return read_droplet_list(path, **args)


def write(tmp_path, text, name="drops.csv"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def refused(path, *parts, **kw):
    """Read, expect a DropletListError whose one-line message contains every part; return the error."""
    with pytest.raises(DropletListError) as info:
        read(path, **kw)
    msg = str(info.value)
    assert "\n" not in msg and str(path) in msg
    for part in parts:
        assert part in msg, (part, msg)
    return info.value


GOOD = "x,y,z,diameter\n0.01,0.01,0.02,0.001\n"


# --- valid files ---------------------------------------------------------------------------------------------------

def test_round_trip_with_density_comments_and_any_column_order(tmp_path):
    path = write(tmp_path, "# initial droplets\n"
                           "density, diameter ,x,y,z\n"
                           "\n"
                           "5200.5,0.001,0.010,0.011,0.0123456789012345  # a trailing comment\n"
                           "# between rows\n"
                           "6100,2.5e-3,0.03,0.02,0.05\n")
    store = read(path)
    assert store.count == 2 and store.capacity >= 1024
    np.testing.assert_array_equal(store.position[:2], [[0.010, 0.011, 0.0123456789012345], [0.03, 0.02, 0.05]])
    np.testing.assert_array_equal(store.diameter[:2], [0.001, 2.5e-3])
    np.testing.assert_array_equal(store.density[:2], [5200.5, 6100.0])
    np.testing.assert_array_equal(store.velocity[:2], 0.0)


def test_default_density_when_column_absent(tmp_path):
    store = read(write(tmp_path, GOOD + "0.02,0.02,0.02,0.002\n"))
    assert store.count == 2
    np.testing.assert_array_equal(store.density[:2], [MATTE, MATTE])
    np.testing.assert_array_equal(store.diameter[:2], [0.001, 0.002])


def test_header_only_gives_zero_droplets(tmp_path):
    store = read(write(tmp_path, "# nothing yet\nx,y,z,diameter,density\n"))
    assert store.count == 0


def test_touching_walls_and_small_overlap_accepted(tmp_path):
    # spheres touching the floor and a wall; two overlapping by 0.5 % of a diameter (limit 1 %)
    store = read(write(tmp_path, "x,y,z,diameter\n0.0005,0.01,0.0005,0.001\n0.02,0.01,0.02,0.001\n"
                                 "0.020995,0.01,0.02,0.001\n"))
    assert store.count == 3


def test_columns_constant():
    assert list(COLUMNS) == ["x", "y", "z", "diameter", "density"]
    assert COLUMNS["density"] == "kg/m^3" and COLUMNS["x"] == "m"


# --- the file itself -----------------------------------------------------------------------------------------------

def test_missing_file(tmp_path):
    refused(tmp_path / "nope.csv", "no such file")


def test_folder(tmp_path):
    refused(tmp_path, "folder")


def test_not_utf8(tmp_path):
    path = tmp_path / "latin1.csv"
    path.write_bytes("x,y,z,diameter\n# caf\u00e9\n".encode("latin-1"))
    refused(path, "not UTF-8", "line 2")


def test_empty_file(tmp_path):
    refused(write(tmp_path, ""), "empty", "header line is required")
    refused(write(tmp_path, "# only a comment\n\n", "c.csv"), "empty")


def test_data_without_header(tmp_path):
    refused(write(tmp_path, "0.01,0.01,0.02,0.001\n"), "line 1", "looks like data", "header")


# --- columns -------------------------------------------------------------------------------------------------------

def test_misspelt_column(tmp_path):
    err = refused(write(tmp_path, "x,y,z,diameter,densty\n0.01,0.01,0.02,0.001,5000\n"),
                  "unknown column 'densty'", "did you mean 'density'", "diameter [m]", "density [kg/m^3]")
    assert err.column == "densty" and err.line == 1


def test_unknown_column(tmp_path):
    refused(write(tmp_path, "x,y,z,diameter,colour\n0.01,0.01,0.02,0.001,1\n"), "unknown column 'colour'",
            "required x [m], y [m], z [m], diameter [m]")


def test_missing_required_column(tmp_path):
    refused(write(tmp_path, "x,y,diameter\n0.01,0.01,0.001\n"), "missing required column(s) z")


def test_repeated_column(tmp_path):
    refused(write(tmp_path, "x,y,z,z,diameter\n"), "column 'z'", "twice")


def test_wrong_separator(tmp_path):
    refused(write(tmp_path, "x;y;z;diameter\n"), "unknown column 'x;y;z;diameter'", "separated by commas")


def test_wrong_number_of_values(tmp_path):
    refused(write(tmp_path, GOOD + "0.01,0.02,0.03\n"), "data row 2 (line 3)", "3 values", "4 columns")


# --- cells ---------------------------------------------------------------------------------------------------------

def test_non_numeric_cell(tmp_path):
    err = refused(write(tmp_path, "x,y,z,diameter\n# c\n0.01,0.01,0.02,0.001\n0.01,abc,0.04,0.001\n"),
                  "data row 2 (line 4)", "column 'y'", "'abc' is not a number")
    assert (err.row, err.line, err.column, err.value) == (2, 4, "y", "abc")


def test_empty_cell(tmp_path):
    refused(write(tmp_path, "x,y,z,diameter\n0.01,0.01,,0.001\n"), "data row 1 (line 2)", "column 'z'",
            "empty cell")


def test_nan_value(tmp_path):
    refused(write(tmp_path, "x,y,z,diameter\n0.01,0.01,0.02,0.001\nnan,0.01,0.02,0.001\n"),
            "data row 2 (line 3)", "column 'x'", "value nan", "finite")


def test_inf_value(tmp_path):
    refused(write(tmp_path, "x,y,z,diameter\n0.01,0.01,-inf,0.001\n"), "column 'z'", "value -inf", "finite")


# --- diameters -----------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("value", ["0", "-0.001"])
def test_non_positive_diameter(tmp_path, value):
    refused(write(tmp_path, GOOD + f"0.02,0.02,0.02,{value}\n"), "data row 2 (line 3)", "column 'diameter'",
            f"diameter {float(value):.9g} m", "diameter > 0")


def test_droplet_larger_than_box(tmp_path):
    refused(write(tmp_path, "x,y,z,diameter\n0.025,0.02,0.05,0.045\n"), "data row 1", "column 'diameter'",
            "diameter 0.045 m", "smallest edge 0.04 m")


# --- densities -----------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("value", ["0", "-5200", "3300", "3000"])
def test_density_not_above_slag(tmp_path, value):
    refused(write(tmp_path, "x,y,z,diameter,density\n0.01,0.01,0.02,0.001,5200\n"
                            f"0.02,0.02,0.02,0.001,{value}\n"),
            "data row 2 (line 3)", "column 'density'", f"density {float(value):.9g} kg/m^3",
            "slag density 3300 kg/m^3")


def test_nan_density_names_slag_density(tmp_path):
    refused(write(tmp_path, "x,y,z,diameter,density\n0.01,0.01,0.02,0.001,NaN\n"), "column 'density'",
            "value nan", "slag density 3300 kg/m^3")


def test_default_density_not_above_slag(tmp_path):
    refused(write(tmp_path, GOOD), "no density column", "slag density 3300", default_density=3000.0)


# --- the box -------------------------------------------------------------------------------------------------------

def test_centre_outside_box(tmp_path):
    err = refused(write(tmp_path, GOOD + "0.06,0.01,0.02,0.001\n"), "data row 2 (line 3)", "column 'x'",
                  "(0.06, 0.01, 0.02)", "box (0, 0, 0) to (0.05, 0.04, 0.1)", "centre is outside")
    assert err.column == "x"


def test_droplet_through_the_floor(tmp_path):
    refused(write(tmp_path, "x,y,z,diameter\n0.01,0.01,0.0004,0.001\n"), "data row 1", "column 'z'",
            "reaches the floor", "z - d/2 = -0.0001 m < 0 m")


def test_droplet_through_a_side_wall(tmp_path):
    refused(write(tmp_path, "x,y,z,diameter\n0.01,0.0398,0.05,0.001\n"), "column 'y'",
            "reaches the wall y = 0.04 m")


# --- overlaps ------------------------------------------------------------------------------------------------------

def test_overlapping_pair(tmp_path):
    err = refused(write(tmp_path, "x,y,z,diameter\n0.01,0.01,0.02,0.001\n0.03,0.01,0.02,0.002\n"
                                  "0.0305,0.0105,0.021,0.001\n"),
                  "data rows 2 (line 3) and 3 (line 4)", "overlap by", "smaller diameter",
                  "allowed: overlap <= 0.01 x")
    assert err.row == 2


def test_same_centre(tmp_path):
    # refused even with a generous overlap limit: contacts skip pairs at distance 0
    refused(write(tmp_path, "x,y,z,diameter\n0.02,0.02,0.02,0.001\n0.01,0.01,0.01,0.001\n"
                            "0.02,0.02,0.02,0.002\n"),
            "data rows 1 (line 2) and 3 (line 4)", "same centre (0.02, 0.02, 0.02)", overlap_limit=5.0)


# --- speed ---------------------------------------------------------------------------------------------------------

def test_100000_droplets_fast(tmp_path):
    rng = np.random.default_rng(1)
    spacing = 1.0e-3
    idx = np.indices((50, 40, 50)).reshape(3, -1).T  # 100 000 lattice sites in a 50 x 40 x 50 mm box
    pos = (idx + 0.5) * spacing
    diam = rng.uniform(0.3e-3, 0.9e-3, len(pos))
    dens = rng.uniform(4500.0, 6000.0, len(pos))
    lines = ["x,y,z,diameter,density"] + [f"{a!r},{b!r},{c!r},{e!r},{f!r}"
                                          for (a, b, c), e, f in zip(pos.tolist(), diam.tolist(), dens.tolist())]
    path = write(tmp_path, "\n".join(lines) + "\n")
    start = time.perf_counter()
    store = read(path, upper=(0.05, 0.04, 0.05))
    elapsed = time.perf_counter() - start
    assert store.count == 100_000
    np.testing.assert_array_equal(store.position[:100_000], pos)
    np.testing.assert_array_equal(store.diameter[:100_000], diam)
    np.testing.assert_array_equal(store.density[:100_000], dens)
    assert elapsed < 2.0, elapsed
