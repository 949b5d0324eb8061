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
