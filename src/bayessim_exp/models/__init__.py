"""Posterior models q(theta | x) and the mixture algebra around them."""
