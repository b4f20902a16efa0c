"""Posterior predictive check by replay: how far does each real trajectory lie from simulated ones?

For real trajectory i, `num` parameter draws from the posterior and `num` from the prior are each
replayed from trajectory i's initial state under its actions (diagnostics/replay.py). The distance
between two trajectories is the root-mean-square over steps 1..T and observation features of their
difference divided by s, the per-feature spread of the prior's replays.

Per trajectory the check reports the median distance of the real trajectory to the posterior's and
to the prior's replays, and a predictive p-value: with D(y) = mean distance of y to the posterior
replays, p = (1 + #{j : D(replay_j) >= D(real)}) / (m + 1), D(replay_j) taken over the other
replays, m the replays that did not diverge (at most num). If the real trajectory were a draw from
the posterior predictive it would be exchangeable with the replays and p would be uniform (in steps
of 1 / (m + 1)); a small p means the real
trajectory lies farther from every posterior draw than posterior draws lie from each other.

Simulations are deterministic and no model is exact, so once the posterior is narrow a small p alone
is expected even for a good model (an independent rigid-rod pendulum integrated by RK4 gives p near
0.01 after three rounds; docs/statistics.md). A trajectory is therefore flagged only when p <= alpha
and its distance to the posterior replays is also more than `max_distance_ratio` of its distance to
the prior's: the posterior leaves a sizeable part of what the prior could not explain unexplained.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import torch

from ..sim.trajectories import Trajectories


@dataclasses.dataclass
class ReplayCheck:
    distance_posterior: list[float]
    distance_prior: list[float]
    p_value: list[float]
    alpha: float
    max_distance_ratio: float
    real: Trajectories
    posterior_states: torch.Tensor  # [n, num, T+1, S] replays at posterior draws
    prior_states: torch.Tensor

    @property
    def flagged(self) -> list[int]:
        """The real trajectories the posterior does not explain (see the module docstring)."""
        return [i for i, (p, post, prior) in enumerate(zip(self.p_value, self.distance_posterior, self.distance_prior))
                if p <= self.alpha and post > self.max_distance_ratio * prior]

    def record(self) -> dict:
        """What results.json keeps (per real trajectory, in the file's order)."""
        return {"distance_posterior": self.distance_posterior, "distance_prior": self.distance_prior,
                "p_value": self.p_value, "alpha": self.alpha, "max_distance_ratio": self.max_distance_ratio,
                "flagged": self.flagged}


def _features(states: torch.Tensor, valid: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """states [..., T+1, S] -> flat standardised steps 1..T, zero where not valid, divided by sqrt(count)
    so that Euclidean distances between them are RMS differences."""
    z = states[..., 1:, :] / scale * valid[:, None]
    return z.flatten(-2) / (valid.sum() * states.shape[-1]).clamp_min(1).sqrt()


def replayed_check(simulate: Callable[[torch.Tensor, torch.Tensor], Trajectories], real: Trajectories,
                   posterior, prior, *, num: int, seed: int, alpha: float, max_distance_ratio: float) -> ReplayCheck:
    """simulate(params [N, D], which [N]) replays real trajectory which[k] at params[k] (replay.replay)."""
    n = real.num
    which = torch.arange(n).repeat_interleave(num)
    g = torch.Generator().manual_seed(seed)  # its own stream: the check never moves the inference's draws
    theta_post = posterior.sample((n * num,), generator=g).double()
    theta_prior = prior.sample((n * num,), generator=g).double()
    post = simulate(theta_post, which)
    pri = simulate(theta_prior, which)
    states_post = post.states.double().reshape(n, num, *post.states.shape[1:])
    states_prior = pri.states.double().reshape(n, num, *pri.states.shape[1:])
    ok_post = (~post.diverged).reshape(n, num)
    ok_prior = (~pri.diverged).reshape(n, num)
    scale = states_prior[ok_prior].flatten(0, -2).std(0).clamp_min(1e-6)
    real_states = real.states.double()
    d_post, d_prior, p_values = [], [], []
    for i in range(n):
        valid = real.valid[i].double()
        sims = states_post[i][ok_post[i]]
        if len(sims) < 2:  # every posterior draw diverged on this trajectory's actions
            d_post.append(float("inf")), d_prior.append(float("inf")), p_values.append(0.0)
            continue
        z_sims, z_real = _features(sims, valid, scale), _features(real_states[i], valid, scale)[None]
        to_real = torch.cdist(z_sims, z_real)[:, 0]
        d_sims = torch.cdist(z_sims, z_sims).sum(1) / (len(sims) - 1)  # the diagonal is zero
        d_post.append(float(to_real.median()))
        z_prior = _features(states_prior[i][ok_prior[i]], valid, scale)
        d_prior.append(float(torch.cdist(z_prior, z_real)[:, 0].median()))
        p_values.append(float((1 + (d_sims >= to_real.mean()).sum()) / (len(sims) + 1)))
    return ReplayCheck(d_post, d_prior, p_values, alpha, max_distance_ratio, real, states_post, states_prior)
