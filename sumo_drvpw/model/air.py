"""Air density from ambient pressure and temperature (ideal gas, dry air).

ρ = p / (R_d · T) with p [Pa], T [K] and R_d = 287.058 J/(kg·K), the specific gas constant
of dry air (ISO 2533 / ICAO standard atmosphere). At 101.325 kPa and 20 °C this gives
1.2041 kg/m³ (``constants.RHO_DEFAULT``). Humidity lowers ρ by < 1 % at road conditions
and is neglected.
"""

from __future__ import annotations

import numpy as np

from sumo_drvpw.model.constants import KELVIN, P_STD_KPA, R_DRY_AIR


def air_density(ambient_c, pressure_kpa=P_STD_KPA):
    """Density of dry air [kg/m³] at ``ambient_c`` [°C] and ``pressure_kpa`` [kPa].

    ρ = 1000·p / (R_d·(T + 273.15)) (ideal gas law). Scalars give a float, arrays an array.

    >>> round(air_density(20.0), 4)
    1.2041
    """
    rho = np.asarray(pressure_kpa, float) * 1000.0 / (R_DRY_AIR * (np.asarray(ambient_c, float) + KELVIN))
    return float(rho) if rho.ndim == 0 else rho


#: ISO 2533 standard atmosphere (troposphere): lapse rate [K/m], sea-level temperature [K],
#: molar mass of dry air [kg/mol], universal gas constant [J/(mol·K)]
LAPSE_K_PER_M = 0.0065
T0_K = 288.15
M_AIR = 0.0289644
R_UNIVERSAL = 8.31446


def pressure_at_altitude_kpa(h_m) -> np.ndarray:
    """Standard-atmosphere pressure at altitude h [m] → [kPa] (ISO 2533, troposphere):
    p(h) = p₀·(1 − L·h/T₀)^(g·M/(R·L)).

    >>> round(float(pressure_at_altitude_kpa(520.0)), 2)   # Munich
    95.23
    """
    from sumo_drvpw.model.constants import G

    h = np.asarray(h_m, dtype=float)
    return P_STD_KPA * (1.0 - LAPSE_K_PER_M * h / T0_K) ** (G * M_AIR / (R_UNIVERSAL * LAPSE_K_PER_M))
