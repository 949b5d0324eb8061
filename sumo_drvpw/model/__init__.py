"""The model: the term basis, equations and vehicles as data, physical constants.

The only place a term's value is computed (:mod:`.terms`) and the one vectorized
evaluator of an equation (:mod:`.equations`); built-in equations and vehicles are package
data under ``builtin/``.
"""
