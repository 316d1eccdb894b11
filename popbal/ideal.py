"""Ideal-settler estimates (physics.md section 6) and the exact single-size losses of the reduced model's slag flows.

For a size class settling at u [m/s] through a slag layer of height H [m] with slag residence time tau [s]:

* plug flow, droplets entering spread over the height (Hazen 1904): captured eta = min(1, u tau / H);
* vertically mixed plug flow (Camp 1946): eta = 1 - exp(-u tau / H);
* the reduced model, popbal.slag_flow = 'vertical' (slag fed at the top leaves through the outlet band, so it
  flows down through the layer at w = Q_slag / A): at steady state the band withdraws exactly w / (u + w) of the
  class's flux (the discrete scheme telescopes to the same product), eta = u / (u + w) = (u tau/H) / (1 + u tau/H)
  -- the same as a vertically well-mixed tank;
* the reduced model, popbal.slag_flow = 'horizontal' (a column riding the plug flow, fed at the top during the
  first t_f of its residence): a droplet fed at t0 settles iff u (tau - t0) >= H, so for a feed spread evenly
  over [0, t_f], eta = clip((tau - H/u) / t_f, 0, 1), a sharp cut at u = H / tau (top entry, not spread).

Without coalescence and hindering the model reproduces the last two up to its numerical diffusion; the tests and
the verification report (reports/verification.py) compare them.
"""

from __future__ import annotations

import numpy as np


def plug_flow_capture(velocity, residence_time, height):
    """Hazen's ideal settler: eta = min(1, u tau / H) [-]."""
    return np.minimum(1.0, np.asarray(velocity) * residence_time / height)


def mixed_capture(velocity, residence_time, height):
    """Vertically mixed plug flow: eta = 1 - exp(-u tau / H) [-]."""
    return 1.0 - np.exp(-np.asarray(velocity) * residence_time / height)


def through_flow_capture(velocity, downflow):
    """Reduced model, vertical slag flow: eta = u / (u + w) with w the slag downflow above the outlet [-]."""
    velocity = np.asarray(velocity)
    return velocity / (velocity + downflow)


def top_entry_column_capture(velocity, residence_time, height, feed_window):
    """Reduced model, horizontal slag flow with a top feed over [0, t_f]: clip((tau - H/u)/t_f, 0, 1) [-]."""
    velocity = np.asarray(velocity, dtype=float)
    with np.errstate(divide="ignore"):
        crossing = np.where(velocity > 0.0, height / velocity, np.inf)
    if feed_window <= 0.0:
        return (crossing <= residence_time).astype(float)
    return np.clip((residence_time - crossing) / feed_window, 0.0, 1.0)
