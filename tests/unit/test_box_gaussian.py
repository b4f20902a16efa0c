"""Box probabilities and draws of Gaussians in many dimensions (GHK), against closed forms."""

import math

import pytest
import torch
from scipy import stats

from bayessim_exp.distributions.ghk import ghk, truncated_standard_normal
from bayessim_exp.distributions.mixture import GaussianMixture, TruncatedMixture


def test_truncated_standard_normal_far_in_the_tails():
    lower = torch.tensor([-1.0, 8.0, -30.0, 2.0], dtype=torch.float64)
    upper = torch.tensor([1.0, 9.0, -29.0, float("inf")], dtype=torch.float64)
    u = torch.rand(4, 20_000, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    z, log_mass = truncated_standard_normal(lower[:, None], upper[:, None], u)
    exact = [stats.norm.logcdf(-a) + math.log1p(-math.exp(stats.norm.logcdf(-b) - stats.norm.logcdf(-a)))
             if a > 0 else math.log(stats.norm.cdf(b) - stats.norm.cdf(a)) for a, b in zip(lower.tolist(), upper.tolist())]
    torch.testing.assert_close(log_mass[:, 0], torch.tensor(exact, dtype=torch.float64), rtol=1e-9, atol=1e-9)
    assert ((z >= lower[:, None]) & (z <= upper[:, None])).all()
    means = [stats.truncnorm(a, b).mean() for a, b in zip(lower.tolist(), upper.tolist())]
    torch.testing.assert_close(z.mean(1), torch.tensor(means, dtype=torch.float64), atol=0.02, rtol=0)


def test_ghk_box_probability_of_a_correlated_gaussian_matches_scipy():
    cov = torch.tensor([[1.0, 0.6, 0.2], [0.6, 1.5, -0.3], [0.2, -0.3, 0.8]], dtype=torch.float64)
    mean = torch.tensor([0.3, -0.5, 1.0], dtype=torch.float64)
    low, high = torch.tensor([-1.0, -2.0, 0.5], dtype=torch.float64), torch.tensor([1.0, 0.0, 3.0], dtype=torch.float64)
    _, log_w = ghk(mean, torch.linalg.cholesky(cov), low, high, 50_000, torch.Generator().manual_seed(1))
    estimate = torch.logsumexp(log_w, 0).exp().item() / 50_000
    mvn = stats.multivariate_normal(mean.numpy(), cov.numpy())
    # inclusion-exclusion over the 8 corners of the box
    exact = sum((-1) ** (3 - sum(c)) * mvn.cdf([high[i] if c[i] else low[i] for i in range(3)])
                for c in [(a, b, d) for a in (0, 1) for b in (0, 1) for d in (0, 1)])
    assert estimate == pytest.approx(exact, rel=0.01)


def test_a_hundred_dimensional_posterior_truncated_to_its_box():
    # diagonal: the box mass is a product of 1-D masses (about 1e-17 here), out of Monte Carlo's reach
    d = 100
    mean = torch.linspace(-0.4, 1.6, d, dtype=torch.float64)
    std = torch.full((d,), 0.5, dtype=torch.float64)
    low, high = torch.zeros(d, dtype=torch.float64), torch.ones(d, dtype=torch.float64)
    mix = GaussianMixture(torch.zeros(1), mean[None], torch.diag_embed(std**2)[None])
    trunc = TruncatedMixture(mix, low, high)
    assert not trunc.by_rejection
    a, b = ((low - mean) / std).numpy(), ((high - mean) / std).numpy()
    exact_log_mass = float(sum(math.log(stats.norm.cdf(bi) - stats.norm.cdf(ai)) for ai, bi in zip(a, b)))
    assert exact_log_mass < -35
    assert trunc.log_mass_inside == pytest.approx(exact_log_mass, abs=1e-6)  # diagonal: GHK is exact
    s = trunc.sample((4000,))
    assert ((s >= low) & (s <= high)).all()
    exact_mean = torch.tensor(stats.truncnorm(a, b, loc=mean.numpy(), scale=std.numpy()).mean())
    torch.testing.assert_close(s.mean(0), exact_mean, atol=0.03, rtol=0)
    theta = s[:5]
    torch.testing.assert_close(trunc.log_prob(theta), mix.log_prob(theta) - exact_log_mass, atol=1e-5, rtol=0)
