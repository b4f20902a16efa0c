"""Distributions handed to the Python API by users: ours as they are, torch's independent uniforms and Gaussians
converted, anything else refused at the call rather than deep inside conditioning."""

from __future__ import annotations

import torch

from .base import ParameterDistribution
from .independent import BoxUniform, GaussianPrior


def as_parameter_distribution(dist, what: str = "prior") -> ParameterDistribution | None:
    """The project's distribution for a prior (or proposal): ours as they are, None (a flat improper prior) as it
    is, and torch's independent uniforms and Gaussians over a vector of parameters converted (sbi's BoxUniform is
    an Independent(Uniform)). `what` names the argument in the error."""
    if dist is None or isinstance(dist, ParameterDistribution):
        return dist
    tdist = torch.distributions
    base = dist.base_dist if isinstance(dist, tdist.Independent) and dist.reinterpreted_batch_ndims == 1 else dist
    if isinstance(base, tdist.Uniform) and len(base.batch_shape) == 1:
        return BoxUniform(base.low, base.high)
    if isinstance(base, tdist.Normal) and len(base.batch_shape) == 1:
        return GaussianPrior(base.loc, base.scale)  # untruncated
    raise TypeError(f"{what}={dist!r} is not supported: give api.BoxUniform, api.GaussianPrior or api.LogUniform, "
                    "or torch's Independent(Uniform(low, high), 1) / Independent(Normal(loc, scale), 1) (or a "
                    "Uniform / Normal) over a vector [D] of parameters")
