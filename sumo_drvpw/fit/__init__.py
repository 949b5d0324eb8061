"""Fitting against measured power: stepwise calibration, comparison metrics, the residual tracer (diagnose)."""
