"""popbal's roof and bottom layers (popbal.closures, popbal.driver): steady states against their closed forms, mass
accounting, refusals.

Tier (d) verification of STYLE.md: with coalescence and reaction off and one fed size, a well-mixed layer fed at the
volume flux density j that drains at its droplets' velocity v(phi) holds phi with phi v(phi) = j. The roof's v is
the layer's cloud law c_L phi drho g delta^2 / mu plus the droplets' own hindered settling; the bottom layer's the
hindered settling alone. The closed forms below are solved independently of the model (scipy's brentq on the
shared settling law), so a wrong drain, a wrong volume or a lost inflow shows.
"""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

import popbal
from popbal.closures import roof_coefficient, roof_inventory
from popbal.model import BOTTOM, CHANNEL, OUTER, ROOF
from settler.cases import CaseError
from settler.derived import settling_velocity
from settler.physics import STANDARD_GRAVITY, richardson_zaki_factor

C_L, DELTA = 0.1, 0.005  # the roof law's coefficient [-] and thickness [m] (chosen for the test)
# a quarter of the demo's feed: the bottom layer's flux Q / A then stays below the largest hindered settling flux
# max phi U (1 - phi)^n of the fed size (above it the layer fills and has no steady state, as a settling bed would)
SINGLE_SIZE = ["coalescence.enabled=false", "reaction.enabled=false", "feed.scale_std=0", "slag.feed_rate=0",
               "feed.mass_rate=0.0005",
               "popbal.channel_radius_form=flux", "popbal.channel_radius_factor=4.6", "popbal.channel_coefficient=0.4",
               "popbal.return_flow_ratio=0.05"]
LAYERS = [f"popbal.roof_layer_coefficient={C_L}", f"popbal.roof_thickness={DELTA}", "popbal.bottom_layer_factor=1"]


@pytest.fixture(scope="module")
def steady():
    model = popbal.setup("demo", SINGLE_SIZE + LAYERS + ["popbal.end_time=200", "popbal.output_interval=10"])
    return model, popbal.run(model, progress=False)


def _volume_fraction(result, zone, cell):
    number = result.arrays["number_density"][-1][zone, cell]
    return float((number * math.pi / 6.0 * result.arrays["original_diameter"] ** 3).sum())


def test_roof_layer_holds_its_closed_form_volume_fraction(steady):
    model, result = steady
    case = model.case
    q = case.feed.mass_rate / case.matte.density
    j = q / (math.pi * model.inlet_radius**2)
    drho = case.matte.density - case.slag.density
    own = settling_velocity(case, case.feed.mean_diameter)
    n = model.parameters["hindered_exponent"]

    def balance(phi):
        cloud = C_L * phi * drho * STANDARD_GRAVITY * DELTA**2 / model.viscosity
        return phi * (cloud + own * richardson_zaki_factor(phi, n)) - j

    expected = brentq(balance, 1e-12, 0.5, xtol=1e-15)
    got = _volume_fraction(result, ROOF, -1)
    print(f"\nroof: phi {got:.6g} against {expected:.6g}; matte per area {got * DELTA * 1e6:.1f} um, the dilute "
          f"law without own settling {roof_inventory(j, drho, model.viscosity, C_L) * 1e6:.1f} um")
    assert got == pytest.approx(expected, rel=1e-4)
    # the law's inverse gives back c_L from the inventory it predicts
    assert roof_coefficient(j, roof_inventory(j, drho, model.viscosity, C_L), drho, model.viscosity) \
        == pytest.approx(C_L, rel=1e-12)


def test_roof_drained_as_a_cloud_holds_the_roof_laws_inventory(steady):
    """popbal.roof_drainage = 'cloud': every section leaves the roof at the layer's cloud velocity u_L alone (the
    demo has no slag feed through its roof), so the steady layer holds exactly the roof law's matte per area,
    I = roof_inventory(j, drho, mu, c_L) (j = phi u_L with u_L = c_L phi drho g delta^2 / mu), which is what c_L is
    measured from; 'sizes' (the default: the same run bit for bit) adds the droplets' own settling and holds less."""
    model, sizes = steady
    case = model.case
    cloud_model = popbal.setup("demo", SINGLE_SIZE + LAYERS + ["popbal.end_time=200", "popbal.output_interval=10",
                                                               "popbal.roof_drainage=cloud"])
    cloud = popbal.run(cloud_model, progress=False)
    j = case.feed.mass_rate / case.matte.density / (math.pi * model.inlet_radius**2)
    law = roof_inventory(j, case.matte.density - case.slag.density, model.viscosity, C_L)
    got, own = _volume_fraction(cloud, ROOF, -1) * DELTA, _volume_fraction(sizes, ROOF, -1) * DELTA
    print(f"\nroof matte per area: drained as a cloud {got * 1e6:.3f} um against the law's {law * 1e6:.3f} um; size by "
          f"size {own * 1e6:.3f} um")
    assert got == pytest.approx(law, rel=1e-4)
    assert own < 0.95 * law  # the droplets' own settling matters here, so the check above tests the switch
    assert np.abs(cloud.timeseries["mass_balance_error"]).max() < 1e-10
    same = popbal.run(popbal.setup("demo", SINGLE_SIZE + LAYERS + ["popbal.end_time=200", "popbal.output_interval=10",
                                                                   "popbal.roof_drainage=sizes"]), progress=False)
    assert np.array_equal(same.arrays["number_density"], sizes.arrays["number_density"])


def _assert_mass_kept_and_the_feed_settles(result, after=300.0):
    """The matte balance holds to round-off over the run, and from ``after`` [s] on the matte settles at the rate it
    is fed (the layers and the return flow at steady state)."""
    series = result.timeseries
    assert np.abs(series["mass_balance_error"]).max() < 1e-10
    late = series[series["time"] >= after]
    assert np.polyfit(late["time"], late["mass_settled"], 1)[0] == \
        pytest.approx(np.polyfit(late["time"], late["mass_fed"], 1)[0], rel=1e-3)


def _bottom_closed_form(model, push=0.0, lifted=0.0):
    """The steady bottom layer's phi with phi (U_h(phi) + push) (1 - lifted) = Q / A_box: the single fed size's
    hindered settling plus a drainage velocity push [m/s], a share ``lifted`` of what leaves it going back up (so
    that it passes 1 / (1 - lifted) times the feed), solved with brentq independently of the model."""
    case = model.case
    q = case.feed.mass_rate / case.matte.density
    box = case.geometry.width * case.geometry.depth
    own = settling_velocity(case, case.feed.mean_diameter)
    n = model.parameters["hindered_exponent"]
    # the dilute branch: below the volume fraction 1 / (n + 1) of the largest hindered settling flux
    return brentq(lambda phi: phi * (own * richardson_zaki_factor(phi, n) + push) * (1.0 - lifted) - q / box, 1e-12,
                  1.0 / (n + 1.0), xtol=1e-15)


def test_bottom_layer_holds_its_closed_form_volume_fraction(steady):
    model, result = steady
    expected = _bottom_closed_form(model)
    got = _volume_fraction(result, BOTTOM, 0)
    assert model.bottom_thickness == pytest.approx(model.channel_radius, rel=1e-12)
    print(f"\nbottom: phi {got:.6g} against {expected:.6g}, h_b {model.bottom_thickness * 1e3:.2f} mm")
    assert got == pytest.approx(expected, rel=1e-4)
    # only the layers' own cells hold droplets
    number = result.arrays["number_density"][-1]
    assert not number[ROOF, :-1].any() and not number[BOTTOM, 1:].any()


def test_layers_keep_the_mass_and_settle_the_feed(steady):
    _, result = steady
    series = result.timeseries
    assert np.abs(series["mass_balance_error"]).max() < 1e-10
    late = series[series["time"] >= 150.0]
    flux = np.polyfit(late["time"], late["mass_settled"], 1)[0]
    fed = np.polyfit(late["time"], late["mass_fed"], 1)[0]
    assert flux == pytest.approx(fed, rel=1e-3)  # steady: what is fed settles


def test_layers_keep_the_mass_with_coalescence_and_reaction():
    result = popbal.run(popbal.setup("demo", LAYERS + ["popbal.channel_radius_form=flux",
                                                        "popbal.channel_radius_factor=4.6", "popbal.end_time=20"]),
                        progress=False)
    assert np.abs(result.timeseries["mass_balance_error"]).max() < 1e-10
    assert result.arrays["number_density"][-1][ROOF].sum() > 0.0
    assert result.arrays["number_density"][-1][CHANNEL].sum() > 0.0
    # number accounting with the layers: fed = in slag + settled + lost + coalescence events, the roof's counted
    a, ts = result.arrays, result.timeseries
    merged = a["fed_number"][-1].sum() - ts.droplet_count.iloc[-1] - a["settled_number"][-1].sum() \
        - a["lost_number"][-1].sum()
    assert a["merges"][-1].sum() == pytest.approx(merged, rel=1e-9) and a["merges"][-1][ROOF].sum() > 0.0


def test_slag_feed_flows_through_the_roof_at_the_inlet_velocity():
    """fulldem brings the slag in over the inlet disk, so the roof layer under it drains at u_L + w with
    w = Q_s / A_inlet (cubic: 0.40 mm/s), not at the box-spread Q_s / A_box (0.17 mm/s): the steady layer against
    the balance phi (c_L phi drho g delta^2 / mu + w + U_own (1 - phi)^n) = j solved here."""
    model = popbal.setup("cubic", ["coalescence.enabled=false", "reaction.enabled=false", "feed.scale_std=0",
                                   "popbal.channel_radius_form=flux", "popbal.channel_radius_factor=4.6",
                                   "popbal.channel_coefficient=0.4", "popbal.return_flow_ratio=0.05"] + LAYERS[:2]
                         + ["popbal.end_time=30", "popbal.output_interval=10"])
    result = popbal.run(model, progress=False)
    case = model.case
    inlet = math.pi * (0.5 * case.geometry.inlet_diameter) ** 2
    j = case.feed.mass_rate / case.matte.density / inlet
    w_inlet = case.slag.feed_rate / case.slag.density / inlet
    w_box = case.slag.feed_rate / case.slag.density / (case.geometry.width * case.geometry.depth)
    drho = case.matte.density - case.slag.density
    own = settling_velocity(case, case.feed.mean_diameter)
    n = model.parameters["hindered_exponent"]

    def steady(w):
        def balance(phi):
            cloud = C_L * phi * drho * STANDARD_GRAVITY * DELTA**2 / model.viscosity
            return phi * (cloud + w + own * richardson_zaki_factor(phi, n)) - j
        return brentq(balance, 1e-12, 0.5, xtol=1e-15)

    got = _volume_fraction(result, ROOF, -1)
    print(f"\nroof with slag feed: phi {got:.6g}; balance at the inlet velocity {w_inlet * 1e3:.3f} mm/s "
          f"{steady(w_inlet):.6g}, spread over the box ({w_box * 1e3:.3f} mm/s) {steady(w_box):.6g}")
    assert model.roof_slag_velocity == pytest.approx(w_inlet, rel=1e-12)
    assert got == pytest.approx(steady(w_inlet), rel=1e-4)
    assert abs(steady(w_box) / steady(w_inlet) - 1.0) > 0.02  # the test tells the two apart
    # the dilute law with the slag's velocity, and its inverse
    inventory = roof_inventory(j, drho, model.viscosity, C_L, STANDARD_GRAVITY, w_inlet, DELTA)
    phi = inventory / DELTA
    assert phi * (C_L * phi * drho * STANDARD_GRAVITY * DELTA**2 / model.viscosity + w_inlet) \
        == pytest.approx(j, rel=1e-12)
    assert roof_coefficient(j, inventory, drho, model.viscosity, STANDARD_GRAVITY, w_inlet, DELTA) \
        == pytest.approx(C_L, rel=1e-12)
    assert math.isnan(roof_coefficient(j, 2.0 * j * DELTA / w_inlet, drho, model.viscosity, STANDARD_GRAVITY,
                                       w_inlet, DELTA))  # the slag alone would carry more than the feed
    with pytest.raises(ValueError, match="thickness"):
        roof_inventory(j, drho, model.viscosity, C_L, STANDARD_GRAVITY, w_inlet)


@pytest.mark.parametrize("overrides, names", [
    (["popbal.roof_thickness=0.005"], "roof_layer_coefficient"),
    (["popbal.roof_layer_coefficient=0.1"], "roof_thickness"),
    (["popbal.roof_layer_coefficient=0.1", "popbal.roof_thickness=0.08"], "half the slag height"),
    (LAYERS[:2] + ["popbal.feed_layer_thickness=0.005", "popbal.feed_layer_coefficient=0.03"], "one of them"),
    (LAYERS[:2] + ["popbal.channel_radius_factor=0", "popbal.channel_feed_fraction=0"], "channel zone"),
    (["popbal.bottom_layer_factor=1", "popbal.channel_radius_factor=0", "popbal.channel_feed_fraction=0"],
     "channel zone"),
    (["popbal.bottom_layer_factor=40", "popbal.channel_radius_form=flux", "popbal.channel_radius_factor=4.6"],
     "half the slag height"),
])
def test_layer_keys_that_do_not_go_together_are_refused(overrides, names):
    with pytest.raises(CaseError, match=names):
        popbal.setup("demo", overrides)



# --- the roof's drainage law (popbal.roof_thickness_form = "drainage", popbal.roof_drainage_ratio): the layer's
# droplets leave it at k U_s, so fed at j it holds phi_L = j / (k U_s) and the cloud law's inventory I sets delta

K_DRAIN = 2.4  # roof_drainage_ratio [-] (chosen for the test; the resolved reference runs give 2.3-2.8)
DRAINAGE = [f"popbal.roof_layer_coefficient={C_L}", "popbal.roof_thickness_form=drainage",
            f"popbal.roof_drainage_ratio={K_DRAIN}"]


def _stokes(case):
    d = case.feed.mean_diameter
    return (case.matte.density - case.slag.density) * STANDARD_GRAVITY * d * d / (18.0 * case.slag_viscosity)


@pytest.mark.parametrize("preset", ["demo", "cubic"])  # without and with slag through the roof
def test_drainage_law_sets_the_thickness_that_holds_j_over_k_us(preset):
    """The law's thickness, solved here from j = phi_L (c_L phi_L drho g delta^2 / mu + w) at phi_L = j / (k U_s),
    is the model's, and the cloud law's inventory over it is phi_L (the dilute balance of :func:`roof_inventory`)."""
    model = popbal.setup(preset, SINGLE_SIZE[:3] + DRAINAGE + ["popbal.channel_radius_form=flux",
                                                              "popbal.channel_radius_factor=4.6"])
    case = model.case
    inlet = math.pi * model.inlet_radius**2
    j = case.feed.mass_rate / case.matte.density / inlet
    w = model.roof_slag_velocity
    drho = case.matte.density - case.slag.density
    phi = j / (K_DRAIN * _stokes(case))
    delta = brentq(lambda d: phi * (C_L * phi * drho * STANDARD_GRAVITY * d * d / model.viscosity + w) - j,
                   1e-6, 0.5 * case.geometry.height, xtol=1e-15)
    print(f"\n{preset}: drainage law delta {model.roof_thickness * 1e3:.4f} mm against {delta * 1e3:.4f} mm, phi_L "
          f"{phi:.4g}, slag through the roof {w * 1e3:.3f} mm/s")
    assert (w > 0.0) == (preset == "cubic")
    assert model.roof_thickness == pytest.approx(delta, rel=1e-9)
    inventory = roof_inventory(j, drho, model.viscosity, C_L, STANDARD_GRAVITY, w, model.roof_thickness)
    assert inventory / model.roof_thickness == pytest.approx(phi, rel=1e-12)
    assert model.zone_area[ROOF] * model.cell_height == pytest.approx(inlet * delta, rel=1e-9)


def test_drainage_law_thins_the_roof_as_the_feed_grows():
    """Without slag feed delta = k U_s sqrt(mu / (c_L drho g j)): half at four times the feed, and at twice the
    viscosity U_s sqrt(mu) falls by sqrt(2), as the resolved runs' roofs thin from 5 to 2.5 mm over a fourfold
    Kynch ratio."""
    def thickness(extra):
        return popbal.setup("demo", DRAINAGE + ["popbal.channel_radius_form=flux", "popbal.channel_radius_factor=4.6"]
                            + extra).roof_thickness
    base = thickness([])
    assert thickness(["feed.mass_rate=8.6e-3"]) / base == pytest.approx(0.5, rel=1e-9)
    assert thickness(["slag.viscosity_reference=0.9"]) / base == pytest.approx(2.0**-0.5, rel=1e-6)


@pytest.mark.parametrize("overrides, names", [
    (DRAINAGE + [f"popbal.roof_thickness={DELTA}"], "one of them"),
    ([f"popbal.roof_layer_coefficient={C_L}", f"popbal.roof_thickness={DELTA}", "popbal.roof_drainage_ratio=2.4"],
     "belongs to roof_thickness_form = 'drainage' \\(now 'fixed'\\)"),
    (DRAINAGE[1:], "needs popbal.roof_layer_coefficient"),
    (DRAINAGE[:2], "'drainage': needs popbal.roof_drainage_ratio"),
    (DRAINAGE[:2] + ["popbal.roof_drainage_ratio=0.001"], "carries the layer away"),
])
def test_drainage_keys_that_do_not_go_together_are_refused(overrides, names):
    preset = "cubic" if "0.001" in overrides[-1] else "demo"  # cubic's slag flows through its roof
    with pytest.raises(CaseError, match=names):
        popbal.setup(preset, overrides + ["popbal.channel_radius_form=flux", "popbal.channel_radius_factor=4.6"])

# --- the layers' own kernels and the floor's drainage (popbal.roof_collision_efficiency, roof_shear_coefficient,
# bottom_drain_coefficient): the zone diagnostics of the reference runs measure them apart from the channel's

DRAIN = 0.05  # bottom_drain_coefficient [-] (chosen for the test)


@pytest.fixture(scope="module")
def drained():
    model = popbal.setup("demo", SINGLE_SIZE + LAYERS + [f"popbal.bottom_drain_coefficient={DRAIN}",
                                                          "popbal.end_time=200", "popbal.output_interval=10"])
    return model, popbal.run(model, progress=False)


def test_drained_bottom_layer_holds_its_closed_form_volume_fraction(drained):
    """With the plume driving its droplets into the floor at beta u_s (x the transport factor) on top of their own
    hindered settling, the steady bottom layer holds phi (U_h(phi) + beta u_s) = Q / A_box: less than undrained."""
    model, result = drained
    own = settling_velocity(model.case, model.case.feed.mean_diameter)
    push = DRAIN * model.parameters["plume_velocity"] * model.parameters["transport_factor"]
    expected, undrained = _bottom_closed_form(model, push), _bottom_closed_form(model)
    got = _volume_fraction(result, BOTTOM, 0)
    print(f"\ndrained bottom: phi {got:.6g} against {expected:.6g} (undrained {undrained:.6g}), push "
          f"{push * 1e3:.3f} mm/s against own settling {own * 1e3:.3f} mm/s")
    assert got == pytest.approx(expected, rel=1e-4)
    assert expected < 0.5 * undrained  # the push matters here: the check could not pass with the drain left out
    assert np.abs(result.timeseries["mass_balance_error"]).max() < 1e-10


def _early_layer_merges(zone, layers, end_time, extra):
    """A layer's (``zone``) coalescence events after ``end_time`` [s] of the demo's feed with the ``layers`` keys
    (coalescence on, reaction off), and the result: early, so that merging has not yet changed what the layer holds
    and its events grow linearly with the kernel."""
    model = popbal.setup("demo", layers + ["popbal.channel_radius_form=flux", "popbal.channel_radius_factor=4.6",
                                           "reaction.enabled=false", "popbal.collision_efficiency=1",
                                           "popbal.shear_coefficient=0.5", f"popbal.end_time={end_time}",
                                           f"popbal.output_interval={end_time}"] + extra)
    result = popbal.run(model, progress=False)
    return float(result.arrays["merges"][-1][zone].sum()), result


def _early_roof_merges(extra):
    """The roof layer's events after 0.3 s (no bottom layer)."""
    return _early_layer_merges(ROOF, LAYERS[:2], 0.3, extra)


def test_roof_kernel_keys_scale_the_roof_layers_merges_alone():
    base, reference = _early_roof_merges([])
    same, result = _early_roof_merges(["popbal.roof_collision_efficiency=1", "popbal.roof_shear_coefficient=0.5"])
    # absent, the keys take the channel's values: the same run, bit for bit
    assert np.array_equal(result.arrays["number_density"], reference.arrays["number_density"]) and same == base
    doubled, result = _early_roof_merges(["popbal.roof_collision_efficiency=2"])
    assert base > 0.0 and doubled / base == pytest.approx(2.0, rel=0.02)  # both kernels scale with it
    # drained as a cloud, the roof's droplets still collide at their own velocities (gravitational merges alone, no
    # roof shear): early it merges at least as much as the default roof, which loses a little more to its droplets'
    # own settling, and not 10 % more
    cloud, _ = _early_roof_merges(["popbal.roof_drainage=cloud", "popbal.roof_shear_coefficient=0"])
    sizes, _ = _early_roof_merges(["popbal.roof_shear_coefficient=0"])
    assert 0.0 < sizes <= cloud < 1.1 * sizes
    # the channel's merges do not see the roof's efficiency beyond what the roof sends it (none merged yet)
    assert result.arrays["merges"][-1][CHANNEL].sum() == pytest.approx(reference.arrays["merges"][-1][CHANNEL].sum(),
                                                                         rel=0.02)
    # the shear collisions add linearly in G = roof_shear_coefficient u_L / delta
    no_shear, _ = _early_roof_merges(["popbal.roof_shear_coefficient=0"])
    one, _ = _early_roof_merges(["popbal.roof_shear_coefficient=2"])
    two, _ = _early_roof_merges(["popbal.roof_shear_coefficient=4"])
    print(f"\nroof merges at 0.3 s: {base:.4g}, twice the efficiency {doubled:.4g}; roof shear coefficient 0 / 2 / 4: "
          f"{no_shear:.4g} / {one:.4g} / {two:.4g}")
    assert one > 1.2 * no_shear  # the shear's share is not negligible, so the next check tests it
    assert (two - no_shear) / (one - no_shear) == pytest.approx(2.0, rel=0.02)


EARLY_CHANNEL = ["popbal.channel_radius_form=flux", "popbal.channel_radius_factor=4.6",
                 "popbal.channel_feed_fraction=0.5", "reaction.enabled=false", "popbal.collision_efficiency=1",
                 "popbal.shear_coefficient=0.5", "popbal.end_time=1.0", "popbal.output_interval=1.0"]


def _early_channel_merges(extra):
    """The merges per zone after 1 s of the demo's feed, half into its plume channel and half spread over the outer
    zone (no layers; coalescence on, reaction off): early, so that merging has not yet changed what the zones hold
    much, and the outer zone merges its own feed."""
    model = popbal.setup("demo", EARLY_CHANNEL + extra)
    result = popbal.run(model, progress=False)
    return np.asarray(result.arrays["merges"][-1], dtype=float).sum(axis=1), result  # per zone


def test_channel_efficiency_scales_the_channels_merges_alone():
    """popbal.channel_collision_efficiency multiplies both kernels in the channel zone and nowhere else: absent it is
    collision_efficiency (the same run bit for bit); at twice that the channel's early merges double (2 %), while the
    outer zone's, fed apart and getting nothing from the channel yet, do not move (1e-6)."""
    base, reference = _early_channel_merges([])
    _, same = _early_channel_merges(["popbal.channel_collision_efficiency=1"])
    assert np.array_equal(same.arrays["number_density"], reference.arrays["number_density"])
    doubled, _ = _early_channel_merges(["popbal.channel_collision_efficiency=2"])
    print(f"\nmerges per zone at 1 s (channel, outer, roof, bottom): {base}; channel efficiency 2: {doubled}")
    assert base[CHANNEL] > 0.0 and doubled[CHANNEL] / base[CHANNEL] == pytest.approx(2.0, rel=0.02)
    assert base[OUTER] > 0.0 and doubled[OUTER] == pytest.approx(base[OUTER], rel=1e-6)


def test_channel_efficiency_without_a_channel_is_refused():
    with pytest.raises(CaseError, match="popbal.channel_collision_efficiency = 2.0: sets the kernel of a channel zone this case"):
        popbal.setup("demo", ["popbal.channel_radius_factor=0", "popbal.channel_feed_fraction=0",
                              "popbal.channel_collision_efficiency=2"])


def test_a_collision_radius_mixes_the_channels_droplets_over_the_narrower_of_it_and_the_channel():
    """popbal.channel_collision_radius b: the channel merges as with channel_collision_efficiency = E (R_c / b)^2
    where b < R_c (the same run bit for bit: the droplets mixed over pi b^2 instead of pi R_c^2) and at E where
    b >= R_c (the droplets fill the channel: the run without the key, bit for bit)."""
    radius = popbal.setup("demo", EARLY_CHANNEL).channel_radius
    b = radius / math.sqrt(2.0)  # (R_c / b)^2 = 2 at collision_efficiency 1
    _, by_radius = _early_channel_merges([f"popbal.channel_collision_radius={b!r}"])
    _, by_efficiency = _early_channel_merges([f"popbal.channel_collision_efficiency={(radius / b) ** 2!r}"])
    assert np.array_equal(by_radius.arrays["number_density"], by_efficiency.arrays["number_density"])
    _, wide = _early_channel_merges([f"popbal.channel_collision_radius={2.0 * radius!r}"])
    _, reference = _early_channel_merges([])
    assert np.array_equal(wide.arrays["number_density"], reference.arrays["number_density"])


def test_the_spread_collision_radius_applies_where_the_plume_spreads_alone():
    """spread_channel_collision_radius replaces channel_collision_radius in the spread regime only (zones_core's
    rule: simple spreads, the demo does not), E_ch = E (R_c / b)^2 with the layer's E."""
    keys = ["case.calibration=zones_core", "popbal.channel_collision_radius=0.006",
            "popbal.spread_channel_collision_radius=0.014"]
    for case, b in (("demo", 0.006), ("simple", 0.014)):
        model = popbal.setup(case, keys)
        assert model.channel_radius > b
        assert model.parameters["channel_efficiency"] == pytest.approx(
            model.parameters["efficiency"] * (model.channel_radius / b) ** 2, rel=1e-12)


@pytest.mark.parametrize("extra, message", [
    (["popbal.channel_collision_radius=0.006", "popbal.channel_collision_efficiency=1"],
     "popbal.channel_collision_radius = 0.006 m with popbal.channel_collision_efficiency = 1.0: both set"),
    (["popbal.spread_channel_collision_radius=0.01"],
     "popbal.spread_channel_collision_radius = 0.01 m: the spread plume's collision radius; allowed only with"),
    (["popbal.channel_radius_factor=0", "popbal.channel_feed_fraction=0", "popbal.channel_collision_radius=0.006"],
     "popbal.channel_collision_radius = 0.006 m: sets the kernel of a channel zone this case does not have")])
def test_collision_radii_that_do_not_go_together_are_refused(extra, message):
    with pytest.raises(CaseError, match=message):
        popbal.setup("demo", extra)


def _early_bottom_merges(extra):
    """The bottom layer's events after 5 s: the first droplets have just reached the floor."""
    return _early_layer_merges(BOTTOM, LAYERS, 5, extra)


def test_bottom_shear_coefficient_scales_the_bottom_layers_shear_alone():
    """popbal.bottom_shear_coefficient sets the bottom layer's G = c u_s t / h_b: absent it is shear_coefficient (the
    same run bit for bit); the layer's early shear collisions add linearly in c (2 %), and the channel's merges do
    not move (1e-9: nothing returns from the floor)."""
    base, reference = _early_bottom_merges([])
    same, result = _early_bottom_merges(["popbal.bottom_shear_coefficient=0.5"])
    assert np.array_equal(result.arrays["number_density"], reference.arrays["number_density"]) and same == base
    no_shear, _ = _early_bottom_merges(["popbal.bottom_shear_coefficient=0"])
    one, _ = _early_bottom_merges(["popbal.bottom_shear_coefficient=1"])
    two, result = _early_bottom_merges(["popbal.bottom_shear_coefficient=2"])
    print(f"\nbottom merges at 5 s, bottom shear coefficient 0 / 0.5 (absent) / 1 / 2: {no_shear:.4g} / {base:.4g} / "
          f"{one:.4g} / {two:.4g}")
    assert no_shear > 0.0 and one > 1.5 * no_shear  # the shear's share is not negligible, so the next check tests it
    assert (two - no_shear) / (one - no_shear) == pytest.approx(2.0, rel=0.02)
    assert result.arrays["merges"][-1][CHANNEL].sum() == pytest.approx(reference.arrays["merges"][-1][CHANNEL].sum(),
                                                                         rel=1e-9)


@pytest.mark.parametrize("key", ["roof_collision_efficiency", "roof_shear_coefficient", "bottom_drain_coefficient",
                                 "bottom_shear_coefficient"])
def test_layer_kernel_keys_without_their_layer_are_refused(key):
    with pytest.raises(CaseError, match=f"popbal.{key} = 2.0: sets a layer this case does not have"):
        popbal.setup("demo", [f"popbal.{key}=2"])


def test_roof_drainage_without_a_roof_is_refused():
    with pytest.raises(CaseError, match="popbal.roof_drainage = 'cloud': sets a layer this case does not have"):
        popbal.setup("demo", ["popbal.roof_drainage=cloud"])


# --- the bottom layer's lift into the return flow (popbal.bottom_lift_share, bottom_lift_velocity_ratio): resolved,
# the floor gives its slow droplets back to the return flow (popbal.closures)

LIFT = 0.3  # bottom_lift_share [-] (chosen for the test)


@pytest.fixture(scope="module")
def lifted():
    # u_b far above the fed size's settling: every droplet leaving the layer is lifted with the share LIFT; a return
    # flow ten times the other tests' (u_up 11.5 mm/s) brings the lifted droplets round in a minute, not ten
    model = popbal.setup("demo", SINGLE_SIZE + LAYERS + [f"popbal.bottom_lift_share={LIFT}",
                                                          "popbal.bottom_lift_velocity_ratio=1000",
                                                          "popbal.return_flow_ratio=0.5",
                                                          "popbal.end_time=400", "popbal.output_interval=20"])
    return model, popbal.run(model, progress=False)


def test_lifted_droplets_recirculate_through_the_return_flow_as_their_closed_forms_say(lifted):
    """A share lambda of what leaves the bottom layer goes up the outer zone and comes back down the channel, so at
    steady state the layer passes Q / (1 - lambda): phi U_h(phi) (1 - lambda) = Q / A_box; the outer zone carries
    the lifted flux lambda Q / (1 - lambda) up at u_up - U_h(phi_o): phi_o (u_up - U_h(phi_o)) = lambda Q / ((1 -
    lambda) A_outer); what settles is still the feed, and the mass is kept."""
    model, result = lifted
    case = model.case
    q = case.feed.mass_rate / case.matte.density
    own = settling_velocity(case, case.feed.mean_diameter)
    n = model.parameters["hindered_exponent"]
    u_up = model.return_velocity
    assert u_up > own  # the lifted droplets rise: the closed form below assumes it
    expected, unlifted = _bottom_closed_form(model, lifted=LIFT), _bottom_closed_form(model)
    got = _volume_fraction(result, BOTTOM, 0)
    outer_expected = brentq(lambda phi: phi * (u_up - own * richardson_zaki_factor(phi, n))
                            - LIFT * q / ((1.0 - LIFT) * model.zone_area[OUTER]), 0.0, 0.5, xtol=1e-18)
    outer = _volume_fraction(result, OUTER, model.cells // 2)
    print(f"\nlifted bottom: phi {got:.6g} against {expected:.6g} (unlifted {unlifted:.6g}); outer zone mid-height "
          f"{outer:.4g} against {outer_expected:.4g}")
    assert got == pytest.approx(expected, rel=1e-4)
    assert expected > 1.2 * unlifted  # the lift matters here
    assert outer == pytest.approx(outer_expected, rel=1e-4)
    _assert_mass_kept_and_the_feed_settles(result)


def test_lift_share_falls_with_the_droplets_settling_velocity_over_the_upflow():
    from popbal.closures import lift_share

    u = np.array([0.0, 0.5e-3, 1.0e-3, 3.0e-3])
    share = lift_share(u, 0.14, 1.0e-3)
    assert share == pytest.approx(0.14 * np.exp(-np.array([0.0, 0.25, 1.0, 9.0])), rel=1e-12)
    assert not lift_share(u, 0.0, 1.0e-3).any()


# --- the plume's turn into the return flow above the bottom layer (popbal.bottom_turning_share): resolved, the plume
# gives part of its droplets to the return flow as it turns (popbal.closures)

TURNING = 0.6  # bottom_turning_share [-] (chosen for the test)


def _turning_run(form):
    # a return flow ten times the other tests' (u_up 11.5 mm/s) brings the turned droplets round in a minute
    model = popbal.setup("demo", SINGLE_SIZE + LAYERS + [f"popbal.bottom_turning_share={TURNING}",
                                                          f"popbal.bottom_turning_form={form}",
                                                          "popbal.return_flow_ratio=0.5",
                                                          "popbal.end_time=400", "popbal.output_interval=20"])
    return model, popbal.run(model, progress=False)


@pytest.fixture(scope="module")
def turned():
    return _turning_run("selective")


@pytest.fixture(scope="module")
def turned_uniformly():
    return _turning_run("uniform")


@pytest.mark.parametrize("fixture", ["turned", "turned_uniformly"])
def test_turned_droplets_recirculate_and_the_bottom_layer_passes_the_feed_alone(fixture, request):
    """A share t of what leaves the channel's bottom goes up the outer zone and comes back down the channel: t = T
    (1 - U_h / u_up) in the selective form (U_h the outer zone's bottom cell's hindered settling, which the step
    uses), t = T whatever the size in the uniform one (popbal.closures.turning_share). So at steady state the bottom
    layer passes the feed alone, phi U_h(phi) = Q / A_box as without turning, and the outer zone carries the turned
    flux t Q / (1 - t) up at u_up - U_h(phi_o): phi_o (u_up - U_h(phi_o)) = t Q / ((1 - t) A_outer); what settles is
    the feed, and the mass is kept."""
    model, result = request.getfixturevalue(fixture)
    form = "uniform" if fixture == "turned_uniformly" else "selective"
    case = model.case
    q = case.feed.mass_rate / case.matte.density
    own = settling_velocity(case, case.feed.mean_diameter)
    n = model.parameters["hindered_exponent"]
    u_up = model.return_velocity
    assert u_up > own  # the turned droplets rise: the closed form below assumes it
    bottom_cell = _volume_fraction(result, OUTER, 0)
    t = TURNING if form == "uniform" else TURNING * (1.0 - own * richardson_zaki_factor(bottom_cell, n) / u_up)
    outer_expected = brentq(lambda phi: phi * (u_up - own * richardson_zaki_factor(phi, n))
                            - t * q / ((1.0 - t) * model.zone_area[OUTER]), 0.0, 0.5, xtol=1e-18)
    outer = _volume_fraction(result, OUTER, model.cells // 2)
    got, expected = _volume_fraction(result, BOTTOM, 0), _bottom_closed_form(model)
    print(f"\nturned ({form}): bottom phi {got:.6g} against {expected:.6g}; outer zone mid-height {outer:.4g} "
          f"against {outer_expected:.4g} (t = {t:.4f})")
    assert got == pytest.approx(expected, rel=1e-4)
    assert outer == pytest.approx(outer_expected, rel=1e-4)
    assert outer > 0.5 * t / (1.0 - t) * q / (model.zone_area[OUTER] * u_up)  # the turn matters here
    _assert_mass_kept_and_the_feed_settles(result)


def test_the_two_turning_forms_shares():
    """'uniform' turns T of every size; 'selective' T (1 - min(1, U / u_up))."""
    from popbal.closures import turning_share

    u_up = 4e-3
    u = np.array([0.0, 0.5 * u_up, u_up, 2.0 * u_up])
    assert turning_share(TURNING, u, u_up, uniform=True) == pytest.approx(np.full(4, TURNING), rel=1e-15)
    assert turning_share(TURNING, u, u_up) == pytest.approx(TURNING * np.array([1.0, 0.5, 0.0, 0.0]), rel=1e-15)


def test_a_turning_form_without_a_turn_is_refused():
    with pytest.raises(CaseError, match="popbal.bottom_turning_form = 'uniform': shapes a turn"):
        popbal.setup("demo", SINGLE_SIZE + ["popbal.bottom_turning_form=uniform"])


@pytest.fixture(scope="module")
def circulating():
    # the turn above, and the circulation's profile: the upflow u_up s(z) over the whole height faster than the droplets
    # (entrainment over 0.2 R under the lid, turning over 0.05 R above the floor), the plume entraining the
    # outer zone's droplets above the peak; no hindrance, so that a droplet's velocity is its own everywhere
    model = popbal.setup("demo", SINGLE_SIZE + LAYERS + [f"popbal.bottom_turning_share={TURNING}",
                                                          "popbal.return_flow_ratio=0.5", "popbal.hindered_exponent=0",
                                                          "popbal.entrainment_length=0.2",
                                                          "popbal.turning_length=0.05",
                                                          "popbal.end_time=400", "popbal.output_interval=20"])
    return model, popbal.run(model, progress=False)


def test_the_circulation_keeps_the_outer_zones_content_uniform_where_the_plume_entrains(circulating):
    """Steady, every turned droplet comes back to the channel (entrained at its height or over the roof), so the
    channel passes N / (1 - t) and the outer zone takes in t N / (1 - t), t = T (1 - U / u_up), shared over the
    cells below the upflow's peak as the slag they take from the plume: the droplet flux c_j (u_j - U) up through
    cell j is that inflow per unit area times the share taken at or below j; above the peak the plume takes the
    droplets at the slag's rate, so c stays at its value at the peak (popbal.closures, the circulation). And the
    mass is kept."""
    model, result = circulating
    case = model.case
    own = settling_velocity(case, case.feed.mean_diameter)
    upflow = model.return_upflow
    assert upflow.min() > own and upflow.max() == pytest.approx(model.return_velocity, rel=1e-3)
    rate = float(model.feed_number_rate.sum())
    t = TURNING * (1.0 - own / model.return_velocity)
    flux = t * rate / ((1.0 - t) * model.zone_area[OUTER])
    number = result.arrays["number_density"][-1][OUTER].sum(axis=1)
    peak = int(np.argmax(upflow))
    print(f"\ncirculation: peak at cell {peak} of {model.cells}; flux below it over the inflow "
          f"{number[:peak + 1] * (upflow[:peak + 1] - own) / flux}; above it {number[peak:].min():.6g}-"
          f"{number[peak:].max():.6g}")
    assert 3 <= peak <= model.cells - 4
    taken = np.cumsum(model.turning_weight)[:peak + 1]
    assert taken[-1] == pytest.approx(1.0, rel=1e-12) and model.turning_weight[1] > 0.0
    assert number[:peak + 1] * (upflow[:peak + 1] - own) == pytest.approx(flux * taken, rel=1e-4)
    assert number[peak:] == pytest.approx(np.full(model.cells - peak, number[peak]), rel=1e-4)
    assert model.exchange_rate[peak + 1:].min() > 0.0 and not model.exchange_rate[:peak + 1].any()
    _assert_mass_kept_and_the_feed_settles(result)



@pytest.mark.parametrize("fixture, path", [("lifted", "floor_to_outer"), ("turned", "channel_to_outer"),
                                           ("circulating", "channel_to_outer")])
def test_zone_exchange_books_the_recirculating_flux_of_the_closed_forms(fixture, path, request):
    """Result.zone_exchange counts the droplets along each of the return flow's paths. Steady, the share s of the
    flux that passes the bottom layer (lifted: s = lambda) or leaves the channel's bottom (turned: s = t = T (1 - U /
    u_up)) goes round once more, so N s / (1 - s) per second enter the outer zone (N the fed rate) and, none settling
    against the upflow nor merging, as many leave it: over the roof, or into the channel where the plume entrains."""
    model, result = request.getfixturevalue(fixture)
    case = model.case
    own = settling_velocity(case, case.feed.mean_diameter)
    if fixture == "lifted":
        share = LIFT
    else:  # the outer zone's bottom cell is dilute enough here for U_h = U within the tolerance
        share = TURNING * (1.0 - own / model.return_velocity)
    rate = float(model.feed_number_rate.sum()) * share / (1.0 - share)
    ex = result.zone_exchange(300.0, 400.0)
    print(f"\n{fixture}: {ex}; expected {rate:.6g} per s")
    assert ex[path] == pytest.approx(rate, rel=2e-3)
    assert ex["outer_to_top"] + ex["outer_to_channel"] == pytest.approx(rate, rel=2e-3)
    others = {"floor_to_outer", "channel_to_outer"} - {path}
    assert all(ex[name] == 0.0 for name in others) and ex["outer_merged"] == 0.0
    assert (ex["outer_to_channel"] > 0.1 * rate) == (fixture == "circulating")  # only the circulation entrains
    assert ex["outer_residence"] == pytest.approx(ex["outer_count"] / rate, rel=2e-3)

def test_the_circulation_without_a_bottom_layer_turns_the_slow_droplets_where_the_plume_gives_slag_back():
    """Without a bottom layer the channel's slow droplets all turn, 1 - U_h / u_up of them (U_h their own hindered
    settling, not shifted by the profile's smaller upflow over the floor): with the circulation they come in over the
    cells where the plume gives its slag back, and the mass is kept."""
    # u_up 4.6 mm/s, 0.9 of it in the bottom cell: t = 0.87, a droplet goes round about seven times, 25 s each;
    # the outer zone still grows 0.3 % per 100 s at 1 000 s, so the run goes to 3 000 s
    model = popbal.setup("demo", SINGLE_SIZE + ["popbal.return_flow_ratio=0.2", "popbal.hindered_exponent=0",
                                                "popbal.entrainment_length=0.2", "popbal.turning_length=0.01",
                                                "popbal.end_time=3000", "popbal.output_interval=100"])
    result = popbal.run(model, progress=False)
    assert np.abs(result.timeseries["mass_balance_error"]).max() < 1e-10
    case = model.case
    own = settling_velocity(case, case.feed.mean_diameter)
    t = 1.0 - own / model.return_velocity  # steady: the channel passes N / (1 - t), t of it turns
    flux = t * float(model.feed_number_rate.sum()) / ((1.0 - t) * model.zone_area[OUTER])
    number = result.arrays["number_density"][-1][OUTER].sum(axis=1)
    peak = int(np.argmax(model.return_upflow))
    taken = np.cumsum(model.turning_weight)[:peak + 1]
    assert np.count_nonzero(model.turning_weight) > 1
    assert number[:peak + 1] * (model.return_upflow[:peak + 1] - own) == pytest.approx(flux * taken, rel=1e-4)


@pytest.mark.parametrize("overrides, names", [
    (["popbal.entrainment_length=1"], "needs popbal.turning_length"),
    (["popbal.turning_length=0.5"], "needs popbal.entrainment_length"),
    (["popbal.entrainment_length=1", "popbal.turning_length=0.5", "popbal.return_flow_ratio=0"], "return_flow_ratio"),
])
def test_the_circulation_keys_alone_or_without_a_return_flow_are_refused(overrides, names):
    with pytest.raises(CaseError, match=names):
        popbal.setup("demo", SINGLE_SIZE + overrides)


@pytest.mark.parametrize("overrides, names", [
    (["popbal.bottom_turning_share=0.5"], "bottom_layer_factor"),
    (["popbal.bottom_turning_share=0.5", "popbal.bottom_layer_factor=1", "popbal.return_flow_ratio=0",
      "popbal.channel_radius_form=flux", "popbal.channel_radius_factor=4.6"], "return_flow_ratio"),
    (["popbal.bottom_turning_share=1.5"], "bottom_turning_share"),
])
def test_turning_without_a_bottom_layer_or_a_return_flow_is_refused(overrides, names):
    with pytest.raises(CaseError, match=names):
        popbal.setup("demo", overrides)


@pytest.mark.parametrize("overrides, names", [
    (["popbal.bottom_lift_share=0.1"], "bottom_lift_velocity_ratio"),
    (["popbal.bottom_lift_velocity_ratio=0.2"], "bottom_lift_share"),
    (["popbal.bottom_lift_share=0.1", "popbal.bottom_lift_velocity_ratio=0.2", "popbal.return_flow_ratio=0.05",
      "popbal.channel_radius_form=flux", "popbal.channel_radius_factor=4.6"], "bottom_layer_factor"),
    (["popbal.bottom_lift_share=0.1", "popbal.bottom_lift_velocity_ratio=0.2", "popbal.bottom_layer_factor=1",
      "popbal.return_flow_ratio=0", "popbal.channel_radius_form=flux", "popbal.channel_radius_factor=4.6"],
     "return_flow_ratio"),
    (["popbal.bottom_lift_share=1.5"], "bottom_lift_share"),
])
def test_lift_keys_without_what_they_lift_from_or_into_are_refused(overrides, names):
    with pytest.raises(CaseError, match=names):
        popbal.setup("demo", overrides)


def test_the_regime_rule_at_a_reference_radius_does_not_move_with_the_fitted_core():
    """popbal.spread_reference_radius L: the regime's feed Reynolds number rho_s Q / (mu L) at a fixed length. At
    zones_core's boundary 0.66, demo_feed_double_fine (0.62 at 9.5 mm) spreads once R_0 falls to 8.5 mm (0.62 x 9.5
    / 8.5 = 0.69) unless L = 9.5 mm holds it compact; simple (1.24 at 9.5 mm) spreads either way. L without the
    boundary is refused by name."""
    from popbal.model import plume_spreads
    from settler.cases import load_case

    layer = {"case.calibration": "zones_core", "popbal.plume_core_radius": 0.0085}
    for run, at_core, at_reference in (("demo_feed_double_fine", True, False), ("simple", True, True)):
        case_file = f"data/reference/{run}/case.toml"
        assert plume_spreads(load_case(case_file, layer)) is at_core
        assert plume_spreads(load_case(case_file, {**layer, "popbal.spread_reference_radius": 0.0095})) is at_reference
    with pytest.raises(CaseError, match="popbal.spread_reference_radius = 0.0095 m: the length of the regime rule"):
        popbal.setup("demo", ["popbal.confinement=true", "popbal.plume_law=line_force",
                              "popbal.channel_radius_factor=0.5", "popbal.plume_core_radius=0.0095",
                              "popbal.spread_reference_radius=0.0095"])
