"""Distributions restricted to the prior box: exact inside, a clear refusal when almost nothing is inside."""

import pytest
import torch
from torch.distributions import MultivariateNormal

from bayessim_exp.distributions.restricted import Restricted


def test_restricted_normal_stays_in_the_box_and_renormalises():
    dist = MultivariateNormal(torch.zeros(2, dtype=torch.float64), torch.eye(2, dtype=torch.float64))
    box = Restricted(dist, torch.zeros(2), torch.ones(2) * 5)
    s = box.sample((5000,))
    assert ((s >= 0) & (s <= 5)).all()
    assert box.mass_inside == pytest.approx(0.25, abs=0.01)  # a quarter of a centred normal
    lp = box.log_prob(torch.tensor([[0.5, 0.5], [-0.5, 0.5]]))
    assert lp[0].item() == pytest.approx(dist.log_prob(torch.tensor([0.5, 0.5], dtype=torch.float64)).item()
                                         - torch.log(torch.tensor(box.mass_inside)).item())
    assert lp[1].item() == float("-inf")


def test_a_posterior_almost_entirely_outside_the_box_is_refused():
    dist = MultivariateNormal(torch.full((3,), 10.0, dtype=torch.float64), torch.eye(3, dtype=torch.float64))
    with pytest.raises(ValueError, match="inside the prior's support"):
        Restricted(dist, torch.zeros(3), torch.ones(3))
