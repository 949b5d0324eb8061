"""Physical constants and unit factors: the only numeric literals the models share.

SI inside: m, s, kg, rad, W, J. Units appear in names only where data leaves the code.
"""

#: Standard gravity used by the seed paper and by VSP (Jiménez-Palacios 1999) [m/s²].
G = 9.81
#: the largest vehicle mass any input may give [kg] (100 t: a road train; beyond it, a unit error)
MASS_MAX_KG = 1.0e5
#: Default air density at 20 °C, 101.325 kPa (also SUMO's Energy model) [kg/m³].
RHO_DEFAULT = 1.2041
#: Reference ambient temperature of the ``cold`` term factor, that of RHO_DEFAULT [°C].
T_REF_C = 20.0
#: Specific gas constant of dry air [J/(kg·K)].
R_DRY_AIR = 287.058
#: Standard sea-level pressure [kPa].
P_STD_KPA = 101.325
#: 0 °C in kelvin.
KELVIN = 273.15

KMH = 1.0 / 3.6          # km/h → m/s
MPH = 0.44704            # mph → m/s
FT = 0.3048              # ft → m
LBF = 4.4482216152605    # lbf → N
LB = 0.45359237          # lb → kg
RPM = 2.0 * 3.141592653589793 / 60.0  # rpm → rad/s
MILE = 1609.344         # mile → m
GAL = 3.785411784e-3    # US gallon → m³
HP = 745.69987158227022  # mechanical horsepower → W
G_UNIT = 9.80665         # the unit g (standard gravity, by definition: 3rd CGPM 1901) → m/s²

#: below this speed a vehicle stands [m/s]: the chain's ``standstill_aux_w`` applies, the
#: term ``moving`` is 0 (the drive-log spec's standstill tolerance)
STANDSTILL_MPS = 0.1

#: How a cold start's extra energy spreads over a trip: a rate decaying as e^(−t/τ) from
#: the departure [s], so a trip of T seconds takes the share 1 − e^(−T/τ) of it. A fuel
#: chain's ``cold_start_fuel_l`` is measured as FTP bag 1 − bag 3, both 505 s long: τ =
#: 505 s / 3 puts 95 % of it inside the bag that measured it. A battery chain's cabin
#: warm-up: τ = 300 s, as it was calibrated (sumo_drvpw.validation.chain_i3; the i3's heater
#: V·I falls back to its steady level within 5–10 min), a 5–7 kW heater's first minutes.
FTP_BAG1_S = 505.0
FUEL_COLD_START_TAU_S = FTP_BAG1_S / 3.0
CABIN_WARMUP_TAU_S = 300.0

#: Boundary between light and heavy load in the seed paper's Table 3 [W].
HEAVY_LOAD_W = 50_000.0
#: Speed above which the seed paper's Fig. 8 shows VSP underprediction [m/s].
HIGH_SPEED_MPS = 80.0 * KMH

#: Fuels of the energy chain (sumo_drvpw.model.chain): lower heating value [J/kg], density
#: [kg/L] and CO₂ per kg of fuel burnt [kg/kg]. Sources in docs/sources.md ("Fuels"):
#: LHV and density as in JEC Well-to-Wheels v5 (2020) fuel properties (E0 petrol, B0 diesel);
#: CO₂ = carbon mass fraction (petrol 0.865, diesel 0.862) × 44.01/12.011, full oxidation.
FUELS = {
    "gasoline": {"lhv_j_per_kg": 43.2e6, "density_kg_per_l": 0.745, "co2_kg_per_kg": 3.169},
    "diesel": {"lhv_j_per_kg": 43.1e6, "density_kg_per_l": 0.832, "co2_kg_per_kg": 3.158},
}
#: Stoichiometric air/fuel mass ratio of E0 petrol [kg air per kg fuel], from the same carbon
#: mass fraction 0.865 (the rest hydrogen): O₂ for C → CO₂ and H → H₂O, over the mass
#: fraction of O₂ in dry air 0.2314: 14.59 (textbooks: 14.6–14.7). A petrol engine's
#: mass air flow over it is its fuel flow at λ = 1.
AFR_STOICH_GASOLINE = (0.865 / 12.011 + (1 - 0.865) / 1.008 / 4) * 31.998 / 0.2314

#: The fastest a traction battery's state of charge can move [C: its full 0–100 % per hour].
#: Cars' packs deliver up to 2–5 C (a 13-kW Twizy on 6.1 kWh: 2 C; high-power packs with 0–100
#: km/h in 2–3 s: about 10 C); a SOC reading that leaves both neighbours faster than this is
#: a misread, not energy (data/counters.py).
SOC_RATE_MAX_C = 10.0
