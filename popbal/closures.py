"""Channeling closure: the collective velocity of the droplet plume under the inlet (two-zone model).

Derivation. A spherical cloud of radius R holding droplets at volume fraction phi falls through the slag as a drop
of suspension whose excess density is phi (rho_p - rho_s) and whose viscosity equals the slag's (viscosity ratio
1). Its Hadamard-Rybczynski velocity is

    U = (2/3) (phi drho g R^2 / mu) (1 + lam)/(2 + 3 lam),  lam = 1  ->  U = (4/15) phi drho g R^2 / mu,

which, with N = phi R^3/a^3 droplets of radius a and U_St = (2/9) drho g a^2 / mu, is U = U_St (6/5) N a / R:
the falling-cloud result of Nitsche & Batchelor (JFM 340, 1997) quoted in physics.md section 4. In shared-law
form U = stokes_velocity(2R, rho_s + phi drho, rho_s, mu) * hadamard_rybczynski_factor(1) (checked in the tests).

A continuous feed Q [m^3/s] of matte into a channel of radius R_c gives, by conservation of the volume flux, a
channel volume fraction phi = Q / (pi R_c^2 u). With the cloud law u = c_ch phi drho g R_c^2 / mu the two close to

    u_c = sqrt(c_ch Q drho g / (pi mu)),

independent of R_c. For the seed paper's simple case (Q = 0.0086/5100 m^3/s, drho = 1950 kg/m^3, mu = 0.45 Pa s)
u_c = 0.078 m/s and the plume Reynolds number rho_s u_c R_c / mu = 41 for R_c = 75 mm (about 80 on the diameter),
inside the 10-1000 range physics.md section 4 expects. The reduced model applies the *local* form
u_c(z) = c_ch g R_c^2 sum_k phi_k (rho_k - rho_s) / mu in every channel cell (popbal.kernels.cell_properties): it
needs no steady state, lets the front of a starting plume advance as a shock, and relaxes to the expression above.

Two-zone model. The slag column is split into a channel under the inlet (radius R_c = channel_radius_factor x the
inlet radius) and the outer zone (the rest of the box cross-section). A fraction f_ch (channel_feed_fraction) of
the matte feed enters the channel, where droplets move at u_c plus their own hindered settling velocity and collide
by differential settling and by the plume's shear, G = shear_coefficient x u_c / R_c; the rest settles
individually (hindered) in the outer zone, colliding by differential settling only. Parameters, all in the case's
[popbal] section and all to be calibrated against the full engine: c_ch (channel_coefficient, default 4/15 from
the cloud solution), f_ch, the radius factor, shear_coefficient and collision_efficiency.

Feed layer (issue 13, from the full engine's reference runs). The full runs do not feed a plume directly: the fed
droplets first collect in a dense layer under the inlet and only then accelerate into the plume. At the end of the
stored runs (data/reference/<case>/snapshots.npz) the top 5 mm hold 28 % of the simple case's droplets, moving
down at 1.8 mm/s, and the droplets reach the plume's speed only 25-30 mm under the top (simple: 45 mm/s; deep:
3.7 mm/s in the top 5 mm, 12 mm/s from 30 mm down); 42-45 % of all droplets are in the top tenth of the height in
both cases, and a good share of the mergers happens there. The old form, which put every fed droplet straight into
the plume at u_c, held half the simple case's droplets and merged almost none. The layer is the top
``feed_layer_thickness`` (delta) of the channel zone, where the same cloud law applies with the layer's own
coefficient and length scale, u_L = c_L phi drho g delta^2 / mu (``feed_layer_coefficient`` c_L): a slab fed at the
volume flux j per unit area holds phi = j / u_L, so u_L = sqrt(c_L j drho g / mu) delta. Both scaled cases feed
the same matte flux per inlet area (0.48 kg/m^2/s), which is why one (delta, c_L) can describe both.

Axis velocity. ``channel_velocity`` in the shared time series is the *slag's* downward velocity on the axis at
mid-height (settler.output). The droplets of the full runs move slower than the slag on the axis (simple: 36 mm/s
on the centreline against 86 mm/s of slag), as droplets spread over a plume whose slag velocity peaks on the axis.
u_c is the velocity of the droplet-laden cloud (what moves the droplets); the reduced model reports the axis
velocity as ``axis_velocity_ratio`` x u_c (plus the downflow), a calibrated ratio (1: the old form).

Channel radius from the feed's volume flux (issue 13, second round; ``channel_radius_form = "flux"``). The full
runs' channel does not scale with the inlet: at mid-height over the steady windows (data/reference/<case>/
channel_profile.csv) the half-volume radius is 72 mm in simple and 73 mm in cubic (75 mm inlet radius) but 3.0 mm in
deep (10 mm inlet radius), 0.96 and 0.30 inlet radii. What does scale across the three runs is the plume velocity:
the slag runs down the axis at 89.6 mm/s (simple), 101.9 mm/s (cubic) and 12.5 mm/s (deep), and u_s =
sqrt(c Q drho g / (pi mu)) reproduces the simple/deep ratio 7.2 with the feeds' Q drho (ratio 7.5-8.5 with deep's
matte at 4500-5200 kg/m^3) and c = 0.35-0.39 in both, although Q differs 57-fold: the plume law holds, the inlet
size does not enter it. Continuity then sets the radius that carries Q at u_s with a plume volume fraction phi_p,
pi R_c^2 u_s phi_p = Q_ch, so

    R_c = k_R sqrt(Q_ch / (pi u_s)) [m],  k_R = channel_radius_factor = phi_p^(-1/2) [-],
    u_s = sqrt(c_ch Q_ch drho g / (pi mu)) [m/s]  ->  R_c = k_R (Q_ch mu / (pi c_ch drho g))^(1/4),

R_c proportional to Q^(1/4) and independent of the inlet: 2.4 mm (simple, cubic) and 1.0 mm (deep) per unit k_R at
c_ch = 0.37. The full runs' narrowest section of the plume (simple: 12 mm, 30 mm under the roof; deep: 2.9 mm) is
about 5 and 3 of these units, phi_p = 0.04-0.1. Below the neck the simple and cubic runs spread their droplets over
the whole box (a uniform spread would give 80 mm), deep's stay within 3 mm of the axis: no radius law of a single
plume gives both, which is why the channel_radius column is reported but not a target.

The plume's dilution by its Reynolds number (``plume_dilution_reynolds`` Re_d, with the flux form; 2026-12-06).
The remade set's resolved plumes do not hold one volume fraction: the plume core's phi_p (``zone_profile.csv``, the
droplet volume within the half-volume radius at 0.3-0.7 of the height over the steady window) is 0.025-0.047 in
deep's feed in 50 and 150 mm columns (Re ~0.4, a Stokes plume that keeps about the roof layer's concentration),
0.021 and 0.013 in the demo at half and one times its feed at 2.5 mm cells (Re 2.2 and 4.3), 0.005 in simple and
cubic (Re 18): the plume dilutes with the slag it entrains as it gains inertia. With Re = rho_s u_s R_c / mu taken
at the radius that carries Q_ch at u_s with the measured phi_p, phi_p = k_R^-2 / (1 + Re / Re_d) describes these
seven training runs within 19 % rms (k_R 4.92, Re_d 2.3; :func:`analysis.calibration.zones.dilution_from_zones`),
where one volume fraction (the flux form alone) misses them by up to a factor of five. Not described: a plume
that fills its column (deep's feed in the 20 mm column, phi_p 0.007), and the one-cell plumes of the demo's runs
at 5 mm cells (phi_p 0.04-0.10 at Re 0.8-6), a grid effect (data/reference/README.md, grid study).

Droplet transport and the plume Reynolds number (``plume_reynolds_scale`` Re_c). The droplets of the full runs do
not all ride the plume at u_s: on the centreline they move at 0.41 (simple), 0.44 (cubic) and 0.91 (deep) of the
slag's axis velocity. The plume Reynolds number Re = rho_s u_s R_c / mu is ~7 in simple and cubic (with the neck
radius; the runs' count bursts every ~5 s and the spread over the box are those of an unsteady plume) and ~0.3 in
deep (a steady Stokes plume). The closure: the channel zone's droplets move collectively at u_s / (1 + Re/Re_c)
(a dispersion of the plume's droplets into the return flow that grows with the plume's inertia), implemented by
giving the plume cells the coefficient c_ch / (1 + Re/Re_c)^2 in the local cloud law (its steady solution is then
u_s / (1 + Re/Re_c)) and reporting the axis velocity as axis_velocity_ratio x (1 + Re/Re_c) x that velocity, i.e.
u_s itself (axis_velocity_ratio absent = 1). Re_c is a fitted constant; the simple and cubic cases share their
feed and so their Re: fitted on those two alone, Re_c and c_ch are not separable, and only a fit including deep
determines it (analysis.calibrate reports this).

Return flow (``return_flow_ratio`` r; the designed reference set, docs/guide/reduced-model.md). The slag the plume
drives down comes back up outside it. In the full runs the mean upflow over the box at mid-height is a fixed share of
the slag's axis velocity: 2.72, 3.70 and 4.92 mm/s at 0.5, 1 and 2 times the demo's feed against axis velocities of
43.0, 60.4 and 84.0 mm/s (0.063, 0.061, 0.059), 0.057 and 0.063 at half and twice the viscosity, 0.060 in deep:
the return flux grows as the plume's velocity (Q^0.43 over the feed family), not as its core's flux pi R_c^2 u_s
(which grows as Q), because the plume drags slag well beyond its droplet-laden core (the confined Stokes plume's
downflow reaches r ~ 0.46 R whatever the feed). In the narrower columns of deep's feed the share rises (0.11 at
50 mm, 0.31 at 20 mm), as the return flow has less room: a confinement law r(R/a) is the next form to try. The
closure: the outer zone's slag rises at u_up = r u_s (u_s the steady plume velocity), so a droplet there moves down
at U_h(d) - u_up and rises when slower; what rises out of the outer zone's top re-enters the channel at the roof,
and of what leaves the channel's bottom a share min(1, U_h(d) / u_up) settles (the droplet must cross the turning
slag to reach the floor) and the rest enters the outer zone's bottom. Without it (r = 0) every droplet that reaches
the channel's bottom settles, and popbal settles 2.7 times the coalescence-off demo's mass flux.

Confinement (``confinement = true``; ``shared/reference/reduced-model.md`` section 2). A heavy core of radius a
(the channel, a = R_c) in a closed column of radius R = sqrt(W D / pi) (the box's cross-section), unidirectional
Stokes flow, zero net flux through every horizontal section and no slip at R, has the axis velocity
w0 = (F / 4 pi mu) A0 and core-mean velocity (F / 4 pi mu) Am for the force F = pi a^2 phi drho g per unit height,
A0 = 2 ln(R/a) - 1 + x^2, Am = 2 ln(R/a) - 3/2 + 2 x^2 - x^4 / 2, x = a / R; closing F with the core's matte flux
gives w0 = sqrt(c Q drho g / (pi mu)) with c(R/a) = A0^2 / (4 Am) (:func:`confined_plume_coefficient`): the plume
coefficient is a logarithm of the confinement, not a constant. The same solution gives the return flow: the slag
turns upward at r_0, the root in (a, R) of (2 - x^2)(r_0^2 / R^2 - 1) / 2 = ln(r_0 / R) (about 0.46 R), and rises
over r_0 < r < R at a mean velocity S(R/a) w0 (:func:`confined_return_share`; 0.053 at R/a = 10.8, 0.153 at 2.5). With
``confinement`` the model takes u_s = sqrt(c_ch c(R/R_c) Q drho g / (pi mu)) and u_up = r S(R/R_c) u_s: c_ch
(``channel_coefficient``) and r (``return_flow_ratio``) become multipliers of the laws, 1 where they hold as
derived, so that a calibration measures how far the full engine's plume is from the confined Stokes plume. With the
'flux' radius form R_c depends on u_s and u_s on R_c through c(R/R_c); :func:`confined_closure` solves the pair by
fixed-point iteration (c varies as a logarithm, so it converges in a few steps). Measured against the
coalescence-off runs (the transport level of ``settler calibrate --set`` with ``confinement = true``, k_R and E as in
data/calibration/designed.toml, 2026-12-04): c_ch = 0.41 +- 0.11 and r = 0.71 +- 0.13 (correlation -0.45,
discrepancy 0.19 against 0.21 with constants): the full engine's return flow is of the confined Stokes plume's
size, its plume about sqrt(0.41) = 0.64 times as fast, and the two runs' errors (count +12 / -31 %, settling flux
-29 / +4 %, axis velocity -21 / +5 %) are those of the constant closures, so the law does not yet explain why the
deep family's plume is slower; the full runs' plume radius there is about one 5 mm cell (data/reference/README.md).
Plume as a line force (``plume_law = 'line_force'``, added 2026-12-06; docs/guide/reduced-model.md, "the axis
velocity as a confined line force"). The full runs' plume is no uniform core: within the half-volume radius a it holds
half its band's droplets and the rest spreads out. Their axis velocity is, within about 20 % wherever the plume is one
compact channel (demo_feed_half_fine, demo_visc_double_fine, demo_cell_25 and the deep family; not where the droplets
spread over the box), the line force of that half load lambda_c: w0 = lambda_c drho g A0(R/a) / (4 pi mu), no
constant fitted. popbal's channel, of radius R_c (the dilution law, fitted to the full runs' core fraction within a),
holds the load the feed brings at the channel's speed, so the law takes c(R/R_c) = A0 / 4
(:func:`line_force_coefficient`) in place of the uniform core's A0^2 / (4 Am), in u_s and in the cloud law alike:
at R/R_c = 2.6 / 5 / 10, 0.27 / 0.57 / 0.90 against 0.40 / 0.71 / 1.05. The return flow keeps the uniform core's S.
Those figures were measured before 2026-12-05, when the channel's cloud law still had c_ch alone: the droplets and
the reported axis velocity ran at the unconfined sqrt(c_ch Q drho g / (pi mu)) while u_s, the return flow and Re
took c(R/R_c) (1.55 u_s at R/R_c = 2.6); the cloud law now has c_ch c(R/R_c) t^2 and carries the confined u_s
(tests/test_popbal_channel_closure.py), and the measurement is to be made again.

The plume's slag core apart from the droplets' channel (``plume_core_radius`` R_s, with confinement; 2026-12-07).
In the deep family's Stokes plumes the droplets fall packed in a thread (median gap to the nearest neighbour 0.3-0.5
diameters, volume fraction 0.03-0.06 at 0.1-0.3 of the height) inside a slag core of R* = 10.6-19.1 mm: one channel
radius at 5 mm gives their counts (-3 / +8 / +16 % in the 50 / 150 / 20 mm columns) with the plume 26-159 % too
fast, one at 10.5 mm their axis with the counts two to three times too high (docs/guide/reduced-model.md). With
R_s the confined law's coefficient c(R / R_s) and the return share S(R / R_s) are the slag core's, and R_c (the
channel's load, collisions and shear) is capped at R_s: u_s = sqrt(c_ch c(R / R_s) Q drho g / (pi mu)) whatever
R_c, and the cloud law c_ch c(R / R_s) phi drho g R_c^2 / mu still carries u_s (its load is the same line force
spread over pi R_c^2). Measured first with each run's own R*_t as R_s (an oracle). Two bounds make it one closure
for the coalescing training runs (closure set zones_core, docs/guide/reduced-model.md): in a narrow column the core
is at most ``plume_core_column_share`` beta of the column's radius R (deep's feed in its 20 mm column: 0.62), and a
plume whose feed Reynolds number rho_s Q_ch / (mu R_0) (:func:`feed_reynolds`) reaches ``spread_flux_reynolds``
spreads its core over ``spread_core_share`` s of R (simple and cubic: R* / R = 0.42). The boundary is bracketed by
the regime runs (compact at 0.62, spread at 0.70 and 1.24 with R_0 = 9.5 mm), not derived; it does not hold the
coalescence-off demo at 2.5 mm cells, whose plume spreads at 0.31. Taken at the fitted R_0 the rule moves runs
across the boundary as the fit moves R_0: zones_stir's training fit (2026-12-07) stopped at R_0 = 8.9424 mm, where
demo_feed_double_fine and demo_visc_half_fine stand at 0.65999998 against 0.66, and 8.9420 mm spreads them (count
+80 and +63 %).
``spread_reference_radius`` L takes the number at a fixed length instead, rho_s Q_ch / (mu L), the 9.5 mm the
boundary was bracketed at.

The compact core grown with the feed Reynolds number (``plume_core_exponent`` n, ``plume_core_reynolds`` Re_Q,0;
2026-12-08). One R_0 for every compact plume cannot hold the training runs' axis velocities: zones_stir's fits give
deep_w005_fine's -38 % at R_0 = 8.3 mm, where its droplets hold half their load within a = 3.0 mm of the axis, and
the demo's families' a grows from 5.6-8.3 mm at Re_Q = rho_s Q / (mu L) = 0.155 to 21.8-23.6 mm at 0.62 (L = 9.5
mm; docs/guide/reduced-model.md). With n the compact core is R_s = R_0 (Re_Q / Re_Q,0)^n, Re_Q taken at L =
``spread_reference_radius``: a power law in the group, its exponent fitted, not derived. Re_Q sets R_s alone, so
the demo at half its feed and at twice its viscosity (both 0.155) get one core, where their a differ by 1.5 x.
A probe at n = 0.3, R_0 = 9.5 mm, Re_Q,0 = 0.31 (the other values zones_stir's trial fit's, training runs):
deep_w005_fine's axis -8 % (count -17 %, its channel now held within the 4.4 mm core), the demo at twice its feed and
half its viscosity +1 and -4 %, at half its feed +15 %, demo_cell_25 +30 %. The same law gives deep_w002 (deep's
feed in a 20 mm column) deep_w005_fine's 4.4 mm core and its axis +159 %, where zones_stir's column bound (0.62 R =
7.0 mm) held it at +3 %: its inlet, 10 mm in a column of equivalent radius 11.3 mm, spans 0.89 of it, and the feed
settles as a suspension over the column (axis about 1 mm/s) instead of necking into a thread. With
``plume_fill_inlet_share`` phi_in a compact plume whose inlet radius reaches phi_in R takes the column's bound
beta R (``plume_core_column_share``) as its core; the training runs bracket the boundary between 0.66 (the demo's
runs, necked) and 0.89 (deep_w002), and closure set zones_scale takes the midpoint 0.78: a rule from one run on
one side, as the spread rule's. zones_scale's training-only fit (Re_Q,0 = 0.31; 49 model runs): R_0 = 10.2 mm, n =
0.291 +- 0.036, 27 of 36 window means within 10 %, deep_w005_fine within 6 % in all four, discrepancy 0.060 against
zones_stir's 0.092; R_0 and n correlated +0.938, so the set now takes Re_Q,0 = 0.025, where the fit puts R_0 = 4.91
+- 0.15 mm (the same fit by the chain rule; docs/guide/reduced-model.md).

Roof layer (``roof_layer_coefficient`` c_L, ``roof_thickness`` delta; zone "roof"). In the full runs about half of
the demo family's droplets sit in the top 10 mm, under the inlet (data/reference/<run>/zones.csv: the roof layer's
volume fraction 0.019, 0.029 and 0.044 at 0.5, 1 and 2 times the demo's feed, 0.021 and 0.040 at half and twice the
viscosity, one 5 mm cell thick), where the channel's own feed layer (above) puts them in the top cells of a channel
a few millimetres wide. The roof layer is a separate well-mixed compartment of the inlet disk's area A_L and
thickness delta: it takes the channel's share of the feed and, with a bottom layer or a return flow, the droplets
that rise back to the roof, and drains into the channel's top cell at u_L = c_L phi drho g delta^2 / mu (the
cloud law of a slab, as the feed layer's) plus the droplets' own hindered settling. Fed at the volume flux density
j = Q / A_L it holds phi = j / u_L, i.e. a matte volume per unit area

    I = phi delta = sqrt(j mu / (c_L drho g))   (:func:`roof_inventory`; dilute, own settling neglected),

independent of delta. The demo family follows it: I grows as Q^0.61 and mu^0.47 against the law's 0.5 and 0.5,
and c_L = j mu / (drho g I^2) (:func:`roof_coefficient`) is 0.093-0.127 over the five runs. Across geometries it is
not one constant: 0.034 and 0.043 in simple and cubic, 0.014 and 0.058 in deep's 50 and 20 mm columns (where the
"roof" is the 25-31 mm over which the plume accelerates), and 0.044 in the demo at 2.5 mm cells against 0.108 at
5 mm: the roof is one cell thick in the demo family and not resolved there. ``settler calibrate --set --closures
layers`` takes c_L as the geometric mean over the transport runs and delta as their mean thickness.

The slag feed flows through the roof. fulldem brings the slag in as a velocity inlet over the inlet disk
(fulldem.boundaries.InletDisk), so under the inlet the slag moves down at w = Q_s / A_L (cubic: 0.40 mm/s; deep's
cases 0.40 mm/s too, where spread over the box it would be 0.013 mm/s), and the roof layer drains at u_L + w plus
its droplets' hindered settling. The steady layer then holds j = phi (u_L + w), a quadratic in I,
(c_L drho g / mu) I^2 + (w / delta) I = j (:func:`roof_inventory` with ``slag_velocity``; its inverse
:func:`roof_coefficient` measures c_L = (j - w I / delta) mu / (drho g I^2) from a run's zone diagnostics). Below the
roof the slag's downflow stays spread over the box: in the channel it is under 1 % of the plume's velocity (cubic:
0.40 against about 60 mm/s) and in the outer zone the return flow dominates it. With the slag term the roof
coefficients of the paragraph above become 0.036 in cubic (next to simple's 0.034, which has no slag feed: the two
share geometry and feed), 0.013 and 0.044 in deep's 50 and 20 mm columns; the demo family has no slag feed.

The roof's thickness (``roof_thickness_form``). The zone diagnostics count the layer in slices one cell high, so at
5 mm cells every run's roof is one or two cells thick (5-10 mm) and its volume fraction phi_L = I / delta the
cell's, not the layer's. At 3.3 and 2.5 mm cells (the demo's resolved families, demo_re32_fine, the resolved
coalescence-off demo, demo_cell_33 and deep_w002) the layer is 2.5-5 mm thick and thins as the feed flux grows, and
its volume fraction follows the feed flux over the Stokes velocity U_s of the mean fed droplet:
j / (phi_L U_s) = 2.29-2.79 in all eleven, over fourfold feed and viscosity, with and without coalescence, in the
demo's box and deep's 20 mm column (docs/guide/reduced-model.md; at 5 mm cells 2.8-9.4). The layer's droplets
leave it at k U_s, k about 2.5: the drainage law. With ``roof_thickness_form = "drainage"`` popbal sets the roof's
thickness from it (:func:`roof_drainage_thickness`, ``roof_drainage_ratio`` k): the cloud law keeps the inventory I
and the drainage law the volume fraction j / (k U_s), so delta = I / phi_L thins as sqrt(mu / j) U_s, and the roof's
collisions, which go as I^2 / delta, grow with the feed as the full runs' do, where one thickness for every run
put that growth into the roof's efficiency (1.04-1.87 at 4.9 mm over the five resolved demo runs, 0.91-1.16 at each
run's own thickness). ``"fixed"`` (the default) keeps ``roof_thickness``.

Bottom layer (``bottom_layer_factor`` f_b; zone "bottom"). The full runs hold matte just above the floor (demo:
volume fraction 5.8e-3 in the bottom 10 mm against 1e-3 over mid-height; without coalescence 40e-3, 82 000 of 107
000 droplets within 20 mm of the floor), and almost none of it returns with the slag: the upward droplet flux below
the feed layer (lift_by_size.csv, rising count x rising velocity / height) is 0.2-0.6 % of the fed number rate in
the demo family, 2-4 % in simple and cubic, 0.7 % in deep's coalescence-off run, where the return-flow closure
above turns 1 - U / u_up (about 90 % for the fed sizes) of what reaches the channel's bottom. The bottom layer is
a well-mixed compartment over the whole floor, h_b = f_b R_c thick (the plume's discharge spreads about one plume
radius deep; f_b = 1 as derived), that takes everything leaving the channel's and the outer zone's bottom and
drops it on the floor at the droplets' own hindered settling velocity, merging them at its own volume fraction,
with differential settling and the shear G = shear_coefficient u_c / h_b of the plume turning over it. Its steady
state holds phi_b U_h(phi_b) = Q / A_box, which has a solution only below the largest hindered settling flux
max phi U (1 - phi)^n of the droplets (0.029 mm/s for the demo's fresh 0.5 mm matte against its 0.048 mm/s feed
flux): above it the layer fills, as a settling bed would, until coalescence makes its droplets fast enough.

The layers' own kernels and the floor's drainage (``roof_collision_efficiency``, ``roof_shear_coefficient``,
``bottom_drain_coefficient``; absent: the channel's efficiency and shear coefficient, no drainage). The remade
reference runs' zone diagnostics (docs/guide/reduced-model.md) measure the roof apart from the channel: its merges
over the collisions of its droplets well mixed over the top tenth under the inlet, with the gravitational and 0.65 x
the shear kernel, are 1.9-3.5 in every training run (the droplets cluster 1.9-3.5 times within the band; cell by
cell the engine merges about one droplet pair per collision), where one efficiency for every zone had to stand for the
channel as well; and the slag's shear there is about 4 over the roof's own residence time, G t_V = 2.8-5.9, where
t_V = delta / u_L is what ``roof_shear_coefficient`` multiplies the inverse of: G = roof_shear_coefficient u_L /
delta. The floor: without coalescence the full runs' droplets cross their bottom 10 mm 1.8-1.9 times faster than they
settle hindered (the demo and deep's feed in its 50 mm column), pushed by the plume's discharge at 0.013-0.03 of
popbal's plume velocity, so the bottom layer's droplets may reach the floor at U_h + bottom_drain_coefficient x
the plume's droplet velocity (transport x u_s); with coalescence they cross 3-13 times faster, mostly by growing.
All three are exploratory closures, not yet calibrated (no stored layer sets them).
The roof's drainage (``roof_drainage``; absent: "sizes"). c_L and k are measured from the full runs' roof layers as j
= phi (u_L + w), the layer draining as one cloud; popbal's roof by default lets each section leave at u_L plus its own
hindered settling, so that it holds less than the law (0.60-0.77 of the coalescing training runs' roof layers, where
merging grows fast droplets) and the roof kernel measured at the law's inventory merges less than the runs' roofs.
``roof_drainage = "cloud"`` drains every section at u_L + w (each still collides at its own velocity): the layer then
holds the law's inventory (0.77-0.97 of those runs' layers). No stored layer sets it (2026-12-07,
docs/guide/reduced-model.md).
The floor's shear (``bottom_shear_coefficient`` c_b; absent: shear_coefficient): G = c_b u_s t / h_b. The full runs'
slag turns far more gently over the floor than the plume's speed over the layer's thickness says: their slag's shear
rate at the bottom band's droplets is 0.11-0.21 of popbal's G at c_b = 1 in the nine coalescing training runs of the
second registration (zones_core's values; 0.5-5.6 /s against 2.9-26 /s), geometric mean 0.157
(:func:`analysis.calibration.zones.floor_shear_from_collisions`; 2026-12-07, docs/guide/reduced-model.md).

The plume channel's own efficiency (``channel_collision_efficiency`` E_ch; absent: collision_efficiency). The
channel holds its droplets well mixed over pi R_c^2, where the full runs' plume keeps them closer to the axis: the
merges under the inlet between the floor's and the roof's height bands over the same droplets' collisions mixed over
popbal's channel section are 1.4 / 2.3 / 5.3 at half / one / twice the demo's feed at 2.5 mm cells, 1.4-1.5 in simple
and cubic, 1.0-2.3 in deep's columns, where cell by cell the engine merges 1.5-2.6 pairs per gravitational collision
(:func:`analysis.calibration.zones.channel_kernel_from_collisions`; 2026-12-06, docs/guide/reduced-model.md).
E_ch multiplies both kernels in the channel zone and nowhere else; no stored layer has it.

The channel's collision radius (``channel_collision_radius`` b, ``spread_channel_collision_radius`` b_s): the law
for E_ch. Cell by cell the full runs' droplets within R_c of the inlet axis collide S times as often as the same
droplets mixed over those grid columns (:mod:`analysis.channel_clustering`), as if mixed over a disk of radius
b = R_eq / sqrt(S); the engine merges E = 0.80 of its cell-by-cell collisions (the kernel run). So popbal's channel
takes E_ch = E max(1, (R_c / b)^2): its droplets collide as if mixed over pi b^2, or over the channel where it is
narrower, and its collisions do not depend on the channel radius a fit takes. On the second registration's training
runs at R_c 9.5 mm (zones_core's start): b 5.3-7.0 mm in the five compact demo runs (S 1.8-3.1), 14.0-14.2 mm in
simple and cubic at 37.5 mm (S 6.7-7.0), the regime's own b; deep_w002's 5 mm channel (12 columns) gives S 0.07,
which the law (E_ch >= E) cannot carry: there the channel merges at E. b shrinks with the cell (8.0 / 6.6 / 5.3 mm
at 5 / 3.3 / 2.5 mm cells in the demo's grid study): the full engine's plume core is not grid-converged (2026-12-07,
docs/guide/reduced-model.md).

The bottom layer's lift into the return flow (``bottom_lift_share`` lambda, ``bottom_lift_velocity_ratio`` beta).
Resolved, the floor does give droplets back. The demo at 2.5 mm cells, continued from its stored 25 s run to 60 s
at the set's engine (exploratory, 2026-12-06; docs/guide/reduced-model.md), holds 3 800-5 600 droplets in the return
flow below the roof, a quarter of the mid-column's, against 600-1 100 in the 5 mm runs. Tracked by ident through
its 1-s snapshots over 35-60 s, of the droplets leaving the bottom tenth of the height 4.5 % go up into the region
outside 10 mm of the axis and the rest settle or merge: by size 0.136 (below 0.5 mm), 0.087 (0.5-0.6 mm), 0.022
(0.6-0.7), 0.008 (0.7-0.8), 0.003 (0.8-1.0) and none above 1 mm, whose own settling velocities are 0.15, 0.71,
1.0, 1.3, 1.9 and above 2.9 mm/s; the slag there rises at 4-5 mm/s at mid-height (the return flow, 0.073 of the
axis velocity where it rises) and at 0.8-1.0 mm/s 6 mm above the floor. So the droplets slower than the upflow at
the floor layer's top are carried off it, by size. The closure: of what leaves the bottom layer in a step, section
k's share lambda exp(-(U_k / u_b)^2) enters the outer zone's bottom cell (where it rises at u_up - U) instead of
settling, U_k the droplets' own hindered settling velocity and u_b = beta u_up (:func:`lift_share`); lambda and beta
are to be measured on the resolved runs (about 0.14 and 0.2 on the one above), not fitted. A bottom layer fed at
the volume rate Q with coalescence off then holds phi U_h(phi) (1 - lambda') = Q / A_box, lambda' the fed size's
share: each droplet passes lambda' / (1 - lambda') times more (tests/test_popbal_layers.py).

The plume's turn into the return flow above the bottom layer (``bottom_turning_share`` T). The bottom layer
was built on the 5 mm runs, whose plume gives almost none of its droplets to the return flow; resolved, it does. In
the continued demo_cell_25 (35-60 s, droplets followed by ident over 5 s; analysis.circulation) the droplets in
sinking slag between the bottom and the top tenth of the height that leave it downward or outward go into rising
slag (67 per s, at 10-50 mm, where the plume gives its slag back) about as often as onto the floor (77 per s), with
the same mean diameter (0.61 and 0.58 mm); in the 5 mm demo runs and in deep none do. The closure: with a bottom
layer, of what leaves the channel's bottom a share T (1 - min(1, U_h / u_up)) turns into the outer zone's bottom
cell, as the whole 1 - min(1, U_h / u_up) does without a bottom layer, and the rest enters the bottom layer. At
steady state without coalescence the bottom layer then passes the feed alone and the outer zone carries
t Q / (1 - t) up, t the fed size's turning share (tests/test_popbal_layers.py). About 0.6 on the run above
(0.47 = T (1 - 1.0 / 3.8)); a constant to be measured on the resolved runs, with deep's 0 asking for a law in the
plume's Reynolds number (7 against 0.3), as the transport closure's dispersion has. That is the 'selective' form
(``bottom_turning_form``, the default); since those turning and settling droplets have the same mean diameter, the
'uniform' form turns the share T of every size (:func:`turning_share`).

The return flow's circulation (``entrainment_length`` a, ``turning_length`` b). The full runs' plume takes the
return flow's slag in under the lid and gives it back above the floor, and the return flow's droplets go with the
slag it takes in (analysis.circulation; docs/guide/reduced-model.md): in the continued demo_cell_25, 80 per second
pass from rising into sinking slag at 40-90 mm, where Q_down grows downward, against 13 reaching the roof, and the
growth of Q_down times the return flow's number density predicts 67 of the 77 per second that pass at 40-90 mm. With
both keys the outer zone's upflow is u_up s(z) (:func:`circulation_profile`, u_up its peak) instead of u_up at every
height, and each cell passes e_j c_j per second into the channel's cell at its height where e_j > 0
(:func:`exchange_rates`), inside the implicit transport (popbal.kernels.transport_two_way), so the exchange keeps
the slag's continuity exactly; where e_j < 0 the slag the plume gives back enters, carrying the droplets that
``bottom_turning_share`` turns out of the channel's bottom outflow, shared over those cells in proportion to the
slag each takes (in the full run they pass into rising slag at 10-50 mm, not at the floor). a and b are measured on
the slag alone (Q_down's shape): 1.12 and 0.54 on the continued demo_cell_25, 0.64 and 0.34 in cubic, 0.72 and 0.38
in the 5 mm demo; the tall columns give slag back all along the height, which the form does not hold.

Both layers integrate dc/dt = inflow - (v / h) c exactly over a step (popbal.driver), so their steady states hold
whatever the step; tests/test_popbal_layers.py checks both against their closed forms (the bottom layer's with and
without its drainage) and that the roof's own kernel keys scale its merges alone.

Not modelled (calibration will tell whether they matter): the exchange of droplets between the zones along the
height (the full runs' plume entrains the return flow's slag and its droplets over its upper part and gives slag
back, with a share of its droplets, below: analysis.circulation and docs/guide/reduced-model.md; the paper's ring
flow, which pulls droplets into the channel, and, in the simple case's lower half, carries them out of the slag
jet), the cloud's break-up, and inertia of the plume (Re > 1).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from settler.physics import STANDARD_GRAVITY

#: Hadamard-Rybczynski coefficient of a cloud with viscosity ratio 1: U = (4/15) phi drho g R^2 / mu.
CLOUD_COEFFICIENT = 4.0 / 15.0


@njit(cache=True)
def cloud_velocity(excess_load, radius, viscosity, coefficient=CLOUD_COEFFICIENT, gravity=STANDARD_GRAVITY):
    """Velocity [m/s] of a cloud of radius R [m] whose excess density is excess_load = sum_k phi_k (rho_k - rho_s)
    [kg/m^3]: c_ch excess_load g R^2 / mu. The one implementation of the closure; the kernels call it per cell."""
    return coefficient * excess_load * gravity * radius * radius / viscosity


def steady_channel_velocity(volume_flux, excess_density, viscosity, coefficient=CLOUD_COEFFICIENT,
                            gravity=STANDARD_GRAVITY):
    """Self-consistent plume velocity u_c = sqrt(c Q drho g / (pi mu)) [m/s] for a matte feed Q [m^3/s]."""
    return math.sqrt(coefficient * volume_flux * excess_density * gravity / (math.pi * viscosity))


def steady_channel_fraction(volume_flux, radius, velocity):
    """Matte volume fraction phi = Q / (pi R^2 u) [-] of a channel of radius [m] carrying Q [m^3/s] at u [m/s]."""
    return volume_flux / (math.pi * radius * radius * velocity) if velocity > 0.0 else 0.0


def feed_reynolds(volume_flux, radius, density_slag, viscosity):
    """The feed's Reynolds number rho_s Q / (mu R) [-] through a core of radius R [m] (the regime's group,
    ``spread_flux_reynolds``)."""
    return density_slag * volume_flux / (viscosity * radius)


def plume_reynolds(velocity, radius, density_slag, viscosity):
    """Plume Reynolds number rho_s u_c R_c / mu [-] (on the radius)."""
    return density_slag * velocity * radius / viscosity


def cloud_profile(z, height, channel_radius, channel_coefficient, layer_thickness=None, layer_coefficient=None):
    """Cloud coefficient [-] and length scale [m] of every channel cell, arrays (J,) for cell centres z (J,) [m].

    Below the feed layer: the plume's c_ch and R_c. In the feed layer (cells whose centre lies within
    ``layer_thickness`` [m] of the top ``height`` [m], and at least the top cell when the thickness is > 0): the
    layer's c_L and delta. ``layer_thickness`` None or 0: no layer (the old form).
    """
    z = np.asarray(z, dtype=float)
    coefficient = np.full(z.shape, float(channel_coefficient))
    radius = np.full(z.shape, float(channel_radius))
    if layer_thickness:
        layer = z >= height - layer_thickness
        layer[np.argmax(z)] = True
        coefficient[layer] = layer_coefficient
        radius[layer] = layer_thickness
    return coefficient, radius


def roof_inventory(volume_flux_density, excess_density, viscosity, coefficient, gravity=STANDARD_GRAVITY,
                   slag_velocity=0.0, thickness=None):
    """Steady matte volume per unit area I = phi delta [m] of a roof layer fed at the volume flux density j [m/s]
    that drains at u_L = c_L phi drho g delta^2 / mu plus the slag's velocity w [m/s] through the inlet
    (``slag_velocity``; module docstring): j = phi (u_L + w), i.e.

        (c_L drho g / mu) I^2 + (w / delta) I - j = 0,

    whose positive root is I; without slag (w = 0) I = sqrt(j mu / (c_L drho g)), independent of the thickness
    delta [m] (``thickness``, needed only where w > 0). Dilute: the droplets' own settling is neglected."""
    a = coefficient * excess_density * gravity / viscosity
    if slag_velocity == 0.0:
        return math.sqrt(volume_flux_density / a)
    if not thickness or thickness <= 0.0:
        raise ValueError(f"thickness = {thickness!r} m: a roof layer with slag flowing through it (slag_velocity = "
                         f"{slag_velocity!r} m/s) needs its thickness > 0")
    b = slag_velocity / thickness
    return 2.0 * volume_flux_density / (b + math.sqrt(b * b + 4.0 * a * volume_flux_density))


def roof_drainage_thickness(volume_flux_density, stokes_velocity, drainage_ratio, excess_density, viscosity,
                            coefficient, gravity=STANDARD_GRAVITY, slag_velocity=0.0):
    """The roof layer's thickness delta [m] under the drainage law (``roof_thickness_form = "drainage"``; module
    docstring): the layer's droplets leave it at k U_s, k = ``drainage_ratio`` [-] times the Stokes velocity U_s [m/s]
    of the mean fed droplet (``stokes_velocity``), so that fed at j [m/s] it holds the volume fraction
    phi_L = j / (k U_s); with the cloud law's drainage u_L = c_L phi drho g delta^2 / mu and the slag's w [m/s]
    through it (j = phi (u_L + w), :func:`roof_inventory`)

        delta = sqrt(mu k U_s (k U_s - w) / (c_L drho g j)),

    so that I / delta = phi_L with I = roof_inventory(j, ..., w, delta). ValueError where the slag alone outruns the
    law's drainage (k U_s <= w) or without feed."""
    drained = drainage_ratio * stokes_velocity
    if not volume_flux_density > 0.0:
        raise ValueError(f"volume_flux_density = {volume_flux_density!r} m/s: the drainage law's thickness needs a "
                         "matte feed")
    if not drained > slag_velocity:
        raise ValueError(f"drainage k U_s = {drained!r} m/s: the slag through the roof ({slag_velocity!r} m/s) alone "
                         "carries the layer away; allowed: k U_s above it")
    return math.sqrt(viscosity * drained * (drained - slag_velocity)
                     / (coefficient * excess_density * gravity * volume_flux_density))


def roof_coefficient(volume_flux_density, inventory, excess_density, viscosity, gravity=STANDARD_GRAVITY,
                     slag_velocity=0.0, thickness=None):
    """c_L = (j - w I / delta) mu / (drho g I^2) [-]: the roof law's coefficient that holds the measured matte volume
    per unit area I [m] at the feed flux density j [m/s] with the slag flowing through the layer at w [m/s] (the
    inverse of :func:`roof_inventory`; without slag j mu / (drho g I^2) and delta [m] is not needed). NaN where
    the slag alone would carry more than the feed (j <= w I / delta: no cloud drainage to measure)."""
    carried = 0.0
    if slag_velocity != 0.0:
        if not thickness or thickness <= 0.0:
            raise ValueError(f"thickness = {thickness!r} m: a roof layer with slag flowing through it "
                             f"(slag_velocity = {slag_velocity!r} m/s) needs its thickness > 0")
        carried = slag_velocity * inventory / thickness
    if volume_flux_density <= carried:
        return math.nan
    return (volume_flux_density - carried) * viscosity / (excess_density * gravity * inventory * inventory)


def flux_channel_radius(volume_flux, velocity, radius_factor):
    """The 'flux' form's channel radius R_c = k_R sqrt(Q_ch / (pi u_s)) [m] for Q_ch [m^3/s] carried at u_s [m/s]
    (continuity at the plume volume fraction 1 / k_R^2); 0 without flux."""
    return radius_factor * math.sqrt(volume_flux / (math.pi * velocity)) if volume_flux > 0.0 and velocity > 0.0 \
        else 0.0


def diluted_channel_radius(volume_flux, velocity, radius_factor, dilution_reynolds, density_slag, viscosity):
    """The flux form's channel radius [m] with the plume's volume fraction diluted by its Reynolds number,
    phi_p = k_R^-2 / (1 + Re / Re_d), Re = rho_s u_s R_c / mu (``plume_dilution_reynolds`` Re_d): continuity
    pi R_c^2 u_s phi_p = Q_ch gives R_c^2 - b R_c - c = 0 with b = k_R^2 Q_ch rho_s / (pi mu Re_d) and
    c = k_R^2 Q_ch / (pi u_s), whose positive root this is (:func:`flux_channel_radius` as Re_d -> infinity;
    module docstring). 0 without flux."""
    if not (volume_flux > 0.0 and velocity > 0.0):
        return 0.0
    b = radius_factor**2 * volume_flux * density_slag / (math.pi * viscosity * dilution_reynolds)
    c = radius_factor**2 * volume_flux / (math.pi * velocity)
    return 0.5 * (b + math.sqrt(b * b + 4.0 * c))


def transport_factor(reynolds, reynolds_scale=None):
    """Droplet transport velocity / the plume's u_s [-]: 1 / (1 + Re / Re_c); 1 when Re_c is None."""
    return 1.0 / (1.0 + reynolds / reynolds_scale) if reynolds_scale else 1.0


def lift_share(settling_velocity, share, lift_velocity):
    """The share lambda exp(-(U / u_b)^2) [-] of the droplets leaving the bottom layer that the return flow lifts
    into the outer zone, for their own hindered settling velocity U [m/s], lambda = ``share`` [-] and the upflow at
    the layer's top u_b = ``lift_velocity`` [m/s] (module docstring, bottom layer's lift); 0 where lambda is 0."""
    u = np.asarray(settling_velocity, dtype=float)
    if not share:
        return np.zeros_like(u)
    return share * np.exp(-(np.maximum(u, 0.0) / lift_velocity) ** 2)


def return_velocity(ratio, plume_velocity):
    """The outer zone's slag upflow u_up = r u_s [m/s] (r [-], u_s the steady plume velocity [m/s]); 0 when r is 0."""
    return ratio * plume_velocity if ratio > 0.0 else 0.0


def circulation_profile(z, height, column_radius, entrainment_length, turning_length, samples=2001):
    """s(z) [-] at heights ``z`` [m]: the return flow's upflow over its peak in a closed column of ``height`` [m],
    (1 - exp(-(H - z) / (a R))) (1 - exp(-z / (b R))) normalised to its largest value over [0, H], R the
    ``column_radius`` [m], a the ``entrainment_length`` and b the ``turning_length`` [column radii]: the plume
    entrains the return flow's slag over about a R under the lid and gives it back over about b R above the floor
    (the circulation paragraph of the module docstring)."""
    def shape(x):
        x = np.asarray(x, dtype=float)
        return -np.expm1(-(height - x) / (entrainment_length * column_radius)) \
            * -np.expm1(-x / (turning_length * column_radius))
    return shape(z) / shape(np.linspace(0.0, height, samples)).max()


def exchange_rates(upflow, cell_height):
    """The outer zone's lateral exchange with the channel [1/s] per cell from its upflow u_j [m/s] at the cell
    centres (cell 0 at the floor, u = 0 below it): e_j = (u_{j-1} - u_j) / dz, positive where the upflow falls with
    height (the plume entrains the slag and the droplets in it at that rate), negative where it grows (the plume
    gives slag back). Continuity of the slag in the donor-cell transport: a cell of uniform content stays uniform
    when it loses e_j of it per second and gains -e_j of slag as full."""
    upflow = np.asarray(upflow, dtype=float)
    below = np.concatenate([[0.0], upflow[:-1]])
    return (below - upflow) / cell_height


def settling_share(settling_velocity, upflow):
    """The share min(1, U / u_up) [-] of the droplets reaching the channel's bottom that settle, for their hindered
    settling velocity U [m/s] against the return upflow u_up [m/s] (1 without upflow)."""
    if upflow <= 0.0:
        return np.ones_like(np.asarray(settling_velocity, dtype=float))
    return np.clip(np.asarray(settling_velocity, dtype=float) / upflow, 0.0, 1.0)


def turning_share(share, settling_velocity, upflow, uniform=False):
    """The share [-] of the droplets leaving the channel's bottom that turn into the return flow, per section, for
    ``bottom_turning_share`` T: T (1 - min(1, U / u_up)) (``bottom_turning_form = "selective"``: the faster a droplet
    settles against the upflow u_up [m/s], the likelier it goes on down), or T for every size (``"uniform"``: the
    box-wide circulation takes droplets of every size, as in the continued demo_cell_25, whose droplets turning into
    rising slag and settling onto the floor have the same mean diameter, 0.61 and 0.58 mm, and in simple's and cubic's
    interior, where every size class from 0.4 to 2 mm is spread over the box alike; analysis.suspension). U [m/s]."""
    velocity = np.asarray(settling_velocity, dtype=float)
    if uniform:
        return np.full(velocity.shape, float(share))
    return share * (1.0 - settling_share(velocity, upflow))


def confined_axis_coefficient(column_to_core):
    """A0 = 2 ln(R/a) - 1 + (a/R)^2 [-]: the confined Stokes plume's axis velocity over F / (4 pi mu) (module
    docstring); NaN for R/a <= 1."""
    if not column_to_core > 1.0:
        return math.nan
    x = 1.0 / column_to_core
    return 2.0 * math.log(column_to_core) - 1.0 + x * x


def confined_plume_coefficient(column_to_core):
    """c(R/a) = A0^2 / (4 Am) [-] of the confined Stokes plume (module docstring): w0 = sqrt(c Q drho g / (pi mu));
    NaN for R/a <= 1."""
    if not column_to_core > 1.0:
        return math.nan
    x = 1.0 / column_to_core
    a0 = confined_axis_coefficient(column_to_core)
    am = 2.0 * math.log(column_to_core) - 1.5 + 2.0 * x * x - 0.5 * x**4
    return a0 * a0 / (4.0 * am)


def line_force_coefficient(column_to_core):
    """c(R/a) = A0 / 4 [-] of the plume as a line force (``plume_law = 'line_force'``, module docstring): the axis
    velocity w0 = lambda drho g A0 / (4 pi mu) of the load lambda [m^3/m] the channel holds, which at lambda = Q / w0
    gives w0 = sqrt(c Q drho g / (pi mu)); NaN for R/a <= 1."""
    return 0.25 * confined_axis_coefficient(column_to_core)


#: The confined plume's coefficient c(R / R_c) by ``popbal.plume_law`` (module docstring; absent: 'uniform_core').
PLUME_LAWS = {"uniform_core": confined_plume_coefficient, "line_force": line_force_coefficient}


def confined_return_radius(column_to_core):
    """r_0 / R [-]: where the confined Stokes plume's slag turns from down to up (x = a / R). Outside the core it
    is the root in (x, 1) of h(y) = (2 - x^2)(y^2 - 1) / 2 - ln y; when the slag already rises at the core's edge
    (h(x) <= 0, R/a below about 1.78) the turn lies inside the core, on its parabolic profile, at
    y^2 = A0 x^2 / (1 - x^2)^2. NaN for R/a <= 1."""
    from scipy.optimize import brentq

    if not column_to_core > 1.0:
        return math.nan
    x = 1.0 / column_to_core
    k = 1.0 - 0.5 * x * x  # h(y) = k (y^2 - 1) - ln y, zero at y = 1 and at the root sought
    if k * (x * x - 1.0) - math.log(x) <= 0.0:  # the edge of the core already rises: the turn is inside it
        return math.sqrt(confined_axis_coefficient(column_to_core) * x * x) / (1.0 - x * x)
    upper = 1.0 / math.sqrt(2.0 * k)  # h has its minimum there, below zero; the root lies between x and it
    return brentq(lambda y: k * (y * y - 1.0) - math.log(y), x, upper, xtol=1e-14)


def confined_return_share(column_to_core):
    """S(R/a) [-]: the confined Stokes plume's mean upflow over r_0 < r < R, over its axis velocity w0 (module
    docstring). In units R = 1, F / mu = 1 (x = a / R, y = r_0 / R): w0 = A0 / (4 pi), G = (2 - x^2) / pi; the
    upward flux equals the downward flux through 0 < r < r_0, which for a turn outside the core is -I with
    I = -G pi (1 - y^2)^2 / 8 + (1 - y^2) / 4 + y^2 ln(y) / 2 the flux between r_0 and R, and for a turn inside the
    core pi w0 y^2 + pi (G - 1 / (pi x^2)) y^4 / 8 (the core's profile w0 + (G - 1 / (pi x^2)) r^2 / 4); the mean
    upflow is that flux over pi (1 - y^2). NaN for R/a <= 1."""
    if not column_to_core > 1.0:
        return math.nan
    x = 1.0 / column_to_core
    y = confined_return_radius(column_to_core)
    g = (2.0 - x * x) / math.pi
    axis = confined_axis_coefficient(column_to_core) / (4.0 * math.pi)
    if y <= x:
        upward = math.pi * axis * y * y + math.pi * (g - 1.0 / (math.pi * x * x)) * y**4 / 8.0
    else:
        upward = g * math.pi * (1.0 - y * y) ** 2 / 8.0 - (1.0 - y * y) / 4.0 - 0.5 * y * y * math.log(y)
    return upward / (math.pi * (1.0 - y * y)) / axis


def confined_closure(volume_flux, excess_density, viscosity, multiplier, column_radius, radius_of, iterations=200,
                     tolerance=1e-12, gravity=STANDARD_GRAVITY, law=confined_plume_coefficient, core_radius=None):
    """(u_s [m/s], R_c [m]) with u_s = sqrt(multiplier c(R/R_c) Q drho g / (pi mu)) and R_c = radius_of(u_s), R the
    column radius [m], c = ``law`` (:data:`PLUME_LAWS`), by fixed-point iteration from c = 1; ValueError if the
    channel reaches the column wall (R_c >= R) or the iteration does not settle. ``core_radius`` R_s [m]: the
    coefficient is c(R/R_s), the slag core's, whatever the droplets' R_c (then no iteration is needed)."""
    if core_radius is not None:
        velocity = steady_channel_velocity(volume_flux, excess_density, viscosity,
                                           multiplier * law(column_radius / core_radius), gravity)
        return velocity, radius_of(velocity)
    coefficient = 1.0
    for _ in range(iterations):
        velocity = steady_channel_velocity(volume_flux, excess_density, viscosity, multiplier * coefficient, gravity)
        radius = radius_of(velocity)
        if not radius < column_radius:
            raise ValueError(f"the channel (radius {radius:.4g} m) reaches the column's equivalent radius "
                             f"{column_radius:.4g} m, where the confined plume has no return flow")
        updated = law(column_radius / radius) if radius > 0.0 else coefficient
        if abs(updated - coefficient) <= tolerance * coefficient:
            return velocity, radius
        coefficient = updated
    raise ValueError(f"the confined plume closure did not settle in {iterations} iterations")
