"""From simulations and real data to a parameter distribution (BayesSim; SimOpt later)."""
