"""Fitting against measured power.

``calibrate`` (stepwise DrvPw), ``physical`` (physical readings, constrained refits, the
physical candidates), ``drivetrain``, ``compare`` and ``trip_energy`` (metrics and per-trip
energy), ``diagnose/`` (the residual tracer), ``wind``, ``repeats`` and ``input_checks``;
the energy chains: ``chain`` (calibration of battery and fuel chains), ``chain_fuel``,
``chain_linear``, ``chain_map``, ``chain_effects``, ``chain_checks``; the streaming engines
for logs larger than memory: ``stream``, ``stream_compare``, ``chain_stream`` and
``engine`` (local or Dask); ``ols`` (sufficient statistics) under them all.
"""
