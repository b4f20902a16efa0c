"""Distributions over simulator parameters: priors, posteriors, proposals, all behind one contract
(`ParameterDistribution`), with mixtures, truncation to the prior's box and importance weighting."""
