"""The model: the term basis, equations and vehicles as data, physical constants.

The only place a term's value is computed (:mod:`.terms`) and the one vectorized
evaluator of an equation (:mod:`.equations`); the energy chain an equation may carry
(:mod:`.chain`, with ``chain_values``, ``chain_sumo`` and ``mmpevem``, SUMO's electric
motor model), SUMO's Energy-model parameters (``energy_params``), the measurement
corrections an equation declares (``measurement``), air density (``air``), vehicles
(``vehicles``) and constants (``constants``); built-in equations and vehicles are
package data under ``builtin/``.
"""
