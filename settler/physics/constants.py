"""Physical constants used by the droplet laws (SI units).

Every constant names its source; nothing here is a tunable parameter.
"""

#: Standard gravity [m/s^2] (CGPM 1901, exact by definition).
STANDARD_GRAVITY = 9.80665

#: Molar gas constant [J/(mol K)] (CODATA 2018, exact).
GAS_CONSTANT = 8.314462618

#: Molar mass of Cu2S [kg/mol]: 2 x 63.546 + 32.06 (IUPAC 2021 standard atomic weights).
MOLAR_MASS_CU2S = (2.0 * 63.546 + 32.06) * 1e-3

#: Molar mass of FeS [kg/mol]: 55.845 + 32.06 (IUPAC 2021 standard atomic weights).
MOLAR_MASS_FES = (55.845 + 32.06) * 1e-3

#: Molar mass of Cu [kg/mol] (IUPAC 2021).
MOLAR_MASS_CU = 63.546e-3
