"""The README's refusal paragraph ("Bad input is refused in one line ...") as a whole: every refusal it lists, through
the command line, exits 2 with one line on stderr that names the key, option or file and the value, and says what
is allowed. Refusals come before any step is taken, so no kernel runs here."""

import pytest

from settler.cli import main

DROPLETS = {
    "unknown column": ("x,y,z,diameter,colour\n0.05,0.05,0.05,1e-3,red\n", "colour"),
    "non-number": ("x,y,z,diameter\n0.05,abc,0.05,1e-3\n", "'abc'"),
    "outside the box": ("x,y,z,diameter\n0.05,0.05,0.5,1e-3\n", "outside"),
    "lighter than the slag": ("x,y,z,diameter,density\n0.05,0.05,0.05,1e-3,1000\n", "density"),
    "at one centre": ("x,y,z,diameter\n0.05,0.05,0.05,1e-3\n0.05,0.05,0.05,1e-3\n", "centre"),
}

#: (what the README lists, argv after 'settler', words the one line must hold).
CASES = [
    ("a key's type", ["info", "demo", "slag.temperature=hot"], ["slag.temperature", "hot"]),
    ("a key's range", ["info", "demo", "slag.viscosity_reference=-1"], ["slag.viscosity_reference", "-1"]),
    ("an unknown key", ["info", "demo", "slag.colour=1"], ["slag.colour"]),
    ("a cell size that does not divide the box", ["full", "demo", "--out", "{out}", "fulldem.cell_size=0.003"],
     ["fulldem.cell_size", "0.003"]),
    ("a grid too large for the memory", ["full", "demo", "--out", "{out}", "fulldem.cell_size=0.0001"],
     ["fulldem.cell_size", "GiB"]),
    ("a smoothing kernel wider than the box", ["full", "demo", "--out", "{out}", "fulldem.sigma_cells=12"],
     ["fulldem.sigma_cells", "12"]),
    ("a DEM step under 5 steps a contact", ["full", "demo", "--out", "{out}", "fulldem.dem_step=0.001"],
     ["fulldem.dem_step", "0.001"]),
    ("a reduced run of more than 1e7 steps", ["reduced", "demo", "--out", "{out}", "popbal.time_step=1e-7"],
     ["popbal.time_step", "1e-07"]),
    ("--end-time -1", ["full", "demo", "--out", "{out}", "--end-time", "-1"], ["--end-time", "-1"]),
    ("--end-time nan", ["reduced", "demo", "--out", "{out}", "--end-time", "nan"], ["--end-time", "nan"]),
    ("--end-time inf", ["full", "demo", "--out", "{out}", "--end-time", "inf"], ["--end-time", "inf"]),
    *[(f"a droplet list: {what}", ["full", "demo", "--out", "{out}", "--droplets", "{droplets}"], ["{droplets}", word])
      for what, (_, word) in DROPLETS.items()],
    ("an output folder that is a file", ["reduced", "demo", "--out", "{file}"], ["{file}"]),
]


@pytest.mark.parametrize("what, argv, words", CASES, ids=[c[0] for c in CASES])
def test_each_refusal_of_the_readme_is_one_line_naming_the_value(what, argv, words, tmp_path, capsys):
    droplets = tmp_path / "droplets.csv"
    if what.startswith("a droplet list"):
        droplets.write_text(DROPLETS[what.split(": ", 1)[1]][0])
    file = tmp_path / "a_file"
    file.write_text("not a folder\n")
    fill = {"out": str(tmp_path / "run"), "droplets": str(droplets), "file": str(file)}
    try:
        status = main([a.format(**fill) for a in argv])
    except SystemExit as exc:  # argparse refuses an option's value itself (after its usage lines)
        status = exc.code
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "error" in line]
    assert status == 2, err
    assert len(lines) == 1, err
    for word in words:
        assert word.format(**fill) in lines[0], lines[0]
    assert "allowed" in lines[0] or "must" in lines[0] or "give" in lines[0] or "use" in lines[0], lines[0]


def test_an_occupied_output_folder_is_refused(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["reduced", "demo", "--out", str(out), "popbal.end_time=1"]) == 0
    capsys.readouterr()
    assert main(["full", "demo", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(out) in err and "--overwrite" in err
