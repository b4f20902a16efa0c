"""Expected coverage of posterior credible regions on held-out simulations.

For held-out pairs (theta_i, x_i) drawn like the training data, a calibrated q(theta | x) puts
theta_i inside its level-L credible region with probability L. Two kinds of region:

- hpd: the highest-density region. theta_i is inside it at level L iff the fraction of posterior
  draws with higher density than theta_i is below L (Monte Carlo, `num_samples` draws).
- central: per parameter, the interval between the (1 - L) / 2 and (1 + L) / 2 marginal quantiles.

The held-out pairs come from the round's proposal, so this checks the fitted q(theta | x) against
the distribution it was trained on, before any proposal correction. Coverage below nominal means
overconfident posteriors, above nominal underconfident ones.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

_CHUNK_ELEMENTS = 1 << 22  # numbers held per chunk of held-out pairs (batched models)


def _chunks(count: int, per_pair: int) -> tuple[torch.Tensor, ...]:
    return torch.arange(count).split(max(1, _CHUNK_ELEMENTS // per_pair))


@torch.no_grad()
def credibility_ranks(model, theta: torch.Tensor, x: torch.Tensor, num_samples: int = 1000,
                      seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """Per held-out pair: the HPD level at which theta_i enters ([N]) and its marginal ranks ([N, D]),
    both fractions of `num_samples` posterior draws of q(theta | x_i). Models with `conditionals`
    (batched mixtures) are checked many pairs at a time; others pair by pair."""
    theta = theta.double()
    if hasattr(model, "conditionals"):
        generator = torch.Generator().manual_seed(seed)
        hpd, marginal = [], []
        for rows in _chunks(len(theta), num_samples * theta.shape[1]):  # draws per pair
            q = model.conditionals(x[rows])
            draws = q.sample(num_samples, generator)  # [S, n, D]
            hpd.append((q.log_prob(draws) > q.log_prob(theta[rows])).double().mean(0))
            marginal.append((draws < theta[rows]).double().mean(0))
        return torch.cat(hpd), torch.cat(marginal)
    hpd, marginal = [], []
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        for theta_i, x_i in zip(theta, x):
            q = model.conditional(x_i)
            draws = q.sample((num_samples,)).double()
            hpd.append((q.log_prob(draws) > q.log_prob(theta_i[None])).double().mean())
            marginal.append((draws < theta_i).double().mean(0))
    return torch.stack(hpd), torch.stack(marginal)


def expected_coverage(model, theta: torch.Tensor, x: torch.Tensor, levels: Sequence[float] = (0.5, 0.9),
                      num_samples: int = 1000, seed: int = 0) -> dict[str, dict[str, float]]:
    """{"hpd": {level: coverage}, "central": {level: coverage averaged over parameters}} (levels as strings,
    ready for results.json)."""
    hpd_level, marginal_rank = credibility_ranks(model, theta, x, num_samples, seed)
    out: dict[str, dict[str, float]] = {"hpd": {}, "central": {}}
    for level in levels:
        out["hpd"][f"{level:g}"] = float((hpd_level < level).double().mean())
        lo, hi = (1 - level) / 2, (1 + level) / 2
        out["central"][f"{level:g}"] = float(((marginal_rank >= lo) & (marginal_rank <= hi)).double().mean())
    return out


@torch.no_grad()
def held_out_gain(model, theta: torch.Tensor, x: torch.Tensor, prior) -> float:
    """Mean over held-out pairs of log q(theta_i | x_i) - log p(theta_i): what the fitted model knows
    beyond the prior (nats; negative: less than the prior). q is the model's conditional before any
    truncation to the prior's box, which can only raise it: a lower bound for models in parameter units,
    exact in probit space."""
    theta = theta.double()
    if hasattr(model, "conditionals"):
        d = theta.shape[1]  # per pair: the precision factors of up to 16 components
        log_q = torch.cat([model.conditionals(x[rows]).log_prob(theta[rows]) for rows in _chunks(len(theta), 16 * d * d)])
    else:
        log_q = torch.stack([model.conditional(x_i).log_prob(theta_i[None])[0] for theta_i, x_i in zip(theta, x)])
    return float((log_q - prior.log_prob(theta)).mean())
