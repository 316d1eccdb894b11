"""The droplet feed: the seed paper's size distribution and an insertion schedule with an exact mean mass rate.

Diameters are d = d_mean * s with the scale factor s ~ Normal(1, std) truncated to [s_min, s_max] (seed paper
Table 3: d_mean = 500 um, std = 0.1, range 0.35-0.65 mm, i.e. s in [0.7, 1.3]).
"""

from dataclasses import dataclass, field

import numpy as np

from .sphere import sphere_mass


def _truncated_normal(std, scale_min, scale_max):
    # scipy.stats is imported here, not at the top: it takes about half a second, and every `settler` command
    # (even --version) imports this module through settler.cases.
    from scipy import stats

    a, b = (scale_min - 1.0) / std, (scale_max - 1.0) / std
    return stats.truncnorm(a, b, loc=1.0, scale=std)


def sample_scale_factors(rng, n, std=0.1, scale_min=0.7, scale_max=1.3):
    """Draw n scale factors s ~ Normal(1, std) truncated to [scale_min, scale_max] (numpy array, [-])."""
    if std == 0.0:
        return np.ones(n)
    return _truncated_normal(std, scale_min, scale_max).rvs(size=n, random_state=rng)


def scale_factor_moment(power, std=0.1, scale_min=0.7, scale_max=1.3):
    """E[s^power] of the truncated-normal scale factor (exact, by quadrature of the truncated density) [-]."""
    if std == 0.0:
        return 1.0
    return float(_truncated_normal(std, scale_min, scale_max).moment(power))


def scale_factor_pdf(s, std=0.1, scale_min=0.7, scale_max=1.3):
    """Probability density of the scale factor at s (zero outside the truncation) [1/-]."""
    return _truncated_normal(std, scale_min, scale_max).pdf(s)


def mean_droplet_mass(mean_diameter, density, std=0.1, scale_min=0.7, scale_max=1.3):
    """Mean mass of a fed droplet, rho pi/6 d_mean^3 E[s^3] [kg]."""
    return sphere_mass(mean_diameter, density) * scale_factor_moment(3, std, scale_min, scale_max)


def droplet_rate(mass_rate, mean_diameter, density, std=0.1, scale_min=0.7, scale_max=1.3):
    """Mean number of droplets fed per second for a matte mass rate [kg/s] -> [1/s]."""
    return mass_rate / mean_droplet_mass(mean_diameter, density, std, scale_min, scale_max)


def table_droplet_rate(mass_rate, diameters, mass_fractions, density):
    """Droplets per second [1/s] of a feed split into size classes: sum_k mass_rate w_k / (rho pi/6 d_k^3).

    diameters [m] and mass fractions w_k [-] (summing to 1) of the classes, e.g. a measured entrainment table.
    """
    d = np.asarray(diameters, dtype=float)
    w = np.asarray(mass_fractions, dtype=float)
    return float(np.sum(mass_rate * w / sphere_mass(d, density)))


@dataclass
class FeedSchedule:
    """Insertion schedule that delivers ``mass_rate`` exactly on average.

    A droplet is released as soon as the mass fed so far, plus half of that droplet, reaches mass_rate * t, so the
    fed mass never strays from mass_rate * t by more than half of the largest droplet: the relative error of the
    mean rate falls as 1/t. Diameters are drawn in blocks from the truncated-normal feed distribution.

    mass_rate [kg/s], mean_diameter [m], density [kg/m^3]; ``seed`` makes the schedule reproducible. The state
    (``fed_mass``, ``time``, the pending diameters and the generator) is plain data and can be checkpointed.
    """

    mass_rate: float
    mean_diameter: float
    density: float
    std: float = 0.1
    scale_min: float = 0.7
    scale_max: float = 1.3
    seed: int | None = None
    block: int = 4096
    fed_mass: float = 0.0
    time: float = 0.0
    _pending: np.ndarray = field(default_factory=lambda: np.empty(0), repr=False)
    _rng: np.random.Generator = field(default=None, repr=False)

    def __post_init__(self):
        if self._rng is None:
            self._rng = np.random.default_rng(self.seed)

    def _refill(self):
        s = sample_scale_factors(self._rng, self.block, self.std, self.scale_min, self.scale_max)
        self._pending = np.concatenate([self._pending, self.mean_diameter * s])

    def advance(self, time):
        """Diameters [m] of the droplets to insert between the previous call and ``time`` [s] (numpy array)."""
        if time < self.time:
            raise ValueError(f"FeedSchedule.advance: time {time} s is before the schedule's time {self.time} s")
        self.time = time
        target = self.mass_rate * time
        released = []
        while True:
            if self._pending.size == 0:
                self._refill()
            masses = sphere_mass(self._pending, self.density)
            fed_after = self.fed_mass + np.cumsum(masses)
            # droplet k is released when the mass before it plus half of it is due
            due = fed_after - 0.5 * masses <= target
            n = int(np.argmin(due)) if not due.all() else due.size
            if n:
                released.append(self._pending[:n])
                self.fed_mass = float(fed_after[n - 1])
                self._pending = self._pending[n:]
            if n < due.size:
                break
        return np.concatenate(released) if released else np.empty(0)
