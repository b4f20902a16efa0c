"""Checks of a fitted posterior: calibration on held-out simulations."""
