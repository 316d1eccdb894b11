"""The slab's channel count (analysis.channels) on velocity fields whose channels are known in closed form, and the
run-identity check (analysis.identity) on two runs that are and are not the same."""

import numpy as np
import pytest

from analysis.channels import MIN_SHARE, count_channels, downflow_runs, profile_at


@pytest.mark.parametrize("k", [1, 2, 3, 5])
def test_k_sine_sheets_are_k_channels(k):
    # w = -sin(2 pi k x / L) on (0, L): k downflow half-waves between rising ones, each 1/k of the downflow (to the
    # midpoint rule's error on 400 cells, below 1e-4)
    length, n = 0.4, 400
    x = (np.arange(n) + 0.5) * length / n
    w = -0.01 * np.sin(2.0 * np.pi * k * x / length)
    runs = downflow_runs(x, w)
    assert len(runs) == k
    for j, run in enumerate(runs):
        assert run["share"] == pytest.approx(1.0 / k, rel=1e-4)
        assert run["centre"] == pytest.approx((j + 0.25) * length / k, abs=length / n)  # a half-wave's midpoint
        assert run["peak"] == pytest.approx(0.01, rel=1e-3)


def test_a_one_cell_flicker_is_not_a_channel():
    x = (np.arange(80) + 0.5) * 5e-3
    w = -0.01 * np.sin(2.0 * np.pi * x / 0.4)  # one channel on the left half
    w[60] = -0.001  # a flicker inside the return flow: 0.1 mm/s against a downflow of about 0.5 m/s x mm summed
    runs = downflow_runs(x, w)
    assert len(runs) == 1
    small = downflow_runs(x, w, min_share=0.0)
    assert len(small) == 2 and small[1]["share"] < MIN_SHARE


def test_no_downflow_no_channel_and_shapes_are_checked():
    assert downflow_runs(np.arange(5.0), np.ones(5)) == []
    with pytest.raises(ValueError, match="1-D arrays of one length"):
        downflow_runs(np.arange(5.0), np.ones(4))


def test_counts_by_height_average_the_slab_thickness():
    # two y layers whose mean has three sheets at mid-height and one at the other heights
    h, length, height = 5e-3, 0.4, 0.1
    xs = (np.arange(80) + 0.5) * h
    zs = (np.arange(20) + 0.5) * h
    x, z, y = np.meshgrid(xs, zs, [0.0, 1.0], indexing="ij")
    mid = np.abs(z - 0.05) < h
    w = np.where(mid, -np.sin(2 * np.pi * 3 * x / length), -np.sin(2 * np.pi * x / length)) * 0.01
    w = w + np.where(y > 0.5, 0.003, -0.003)  # the layers differ; their mean is the sine
    counts = count_channels(x.ravel(), z.ravel(), w.ravel(), height)
    assert [len(counts[f]) for f in (0.25, 0.5, 0.75)] == [1, 3, 1]
    px, pw = profile_at(x.ravel(), z.ravel(), w.ravel(), 0.05)
    assert np.allclose(px, xs) and np.allclose(pw, -0.01 * np.sin(2 * np.pi * 3 * xs / length), atol=1e-15)


def _fake_run(folder, value):
    import pandas as pd

    folder.mkdir()
    import json

    meta = json.dumps({"time": 1.0, "steps": 10, "wall_time": 3.0 + value}).encode()  # the engine's form: JSON bytes
    np.savez(folder / "checkpoint.npz", __meta__=np.frombuffer(meta, np.uint8), u=np.full(4, 1.0),
             w=np.full(4, value))
    pd.DataFrame({"time": [0.0, 1.0], "droplet_count": [0, 10], "wall_time": [0.0, 2.0 + value]}).to_csv(
        folder / "timeseries.csv", index=False)


def test_identity_tells_the_same_run_from_another(tmp_path):
    from analysis.identity import differences, main

    _fake_run(tmp_path / "a", 0.5)
    _fake_run(tmp_path / "b", 0.5)
    _fake_run(tmp_path / "c", 0.25)
    assert differences(tmp_path / "a", tmp_path / "b") == []  # the clock and the metadata may differ
    assert differences(tmp_path / "a", tmp_path / "c") == ["checkpoint.npz: w differs"]
    (tmp_path / "b" / "zones.csv").write_text("time\n0.0\n")
    assert differences(tmp_path / "a", tmp_path / "b") == ["zones.csv: only in b"]
    (tmp_path / "b" / "checkpoint.npz").write_bytes(b"not a zip")
    assert main([str(tmp_path / "a"), str(tmp_path / "b")]) == 2
    assert main([str(tmp_path / "a"), str(tmp_path / "c")]) == 1 and main([str(tmp_path / "a")]) == 2


def test_droplets_in_two_clouds_are_two_channels_and_a_curtain_is_one():
    from analysis.channels import droplet_runs

    rng = np.random.default_rng(5)
    two = np.concatenate([rng.uniform(0.05, 0.10, 4000), rng.uniform(0.25, 0.32, 4000)])
    runs = droplet_runs(two, np.ones(two.size), 0.0, 0.4, 5e-3)
    assert len(runs) == 2
    assert runs[0] == pytest.approx((0.05, 0.10), abs=5e-3) and runs[1] == pytest.approx((0.25, 0.32), abs=5e-3)
    curtain = rng.uniform(0.075, 0.325, 20000)
    wall = np.full(300, 0.012)  # a bin of droplets against an end wall: 1.5 % of the band's volume, not a channel
    runs = droplet_runs(np.concatenate([curtain, wall]), np.ones(20300), 0.0, 0.4, 5e-3)
    assert runs == [pytest.approx((0.075, 0.325), abs=5e-3)]
    assert droplet_runs(np.zeros(0), np.zeros(0), 0.0, 0.4, 5e-3) == []
