"""Posterior estimators q(theta | x): fit on simulations, conditional distributions given a summary."""
