"""The virtual test track (synthetic 8 Hz Prius3 logs with known truth) and planted effects."""
