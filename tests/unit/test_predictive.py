"""Posterior predictive check: a posterior at the true parameters predicts the real summaries better than the prior."""

import torch

from bayessim_exp.diagnostics.predictive import predictive_distances
from bayessim_exp.distributions.independent import BoxUniform
from bayessim_exp.distributions.mixture import GaussianMixture


def test_a_concentrated_posterior_is_closer_than_the_prior():
    prior = BoxUniform(torch.zeros(2, dtype=torch.float64), 4 * torch.ones(2, dtype=torch.float64))
    truth = torch.tensor([1.0, 3.0], dtype=torch.float64)
    posterior = GaussianMixture(torch.zeros(1), truth[None], 0.01 * torch.eye(2)[None])

    def simulate_summaries(theta):
        return torch.cat([theta, theta.sum(-1, keepdim=True)], -1) + 0.05 * torch.randn(len(theta), 3, dtype=theta.dtype)

    x_real = simulate_summaries(truth.expand(3, 2))
    d = predictive_distances(simulate_summaries, x_real, posterior, prior, num=500)
    assert d["posterior"] < 0.2 < 0.6 < d["prior"], d
