"""models/adam.py is torch.optim.Adam's arithmetic (without importing torch.optim and torch._dynamo: tests/unit/test_imports.py)."""

from __future__ import annotations

import pytest
import torch

from bayessim_exp.models.adam import Adam


def _train(make_optimizer, steps: int = 30) -> torch.Tensor:
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Linear(5, 16), torch.nn.ReLU(), torch.nn.Linear(16, 3), torch.nn.Linear(3, 3))
    frozen_until = 10  # the last layer gets no gradient in the first steps: its step count must lag
    optimizer = make_optimizer(list(net.parameters()))
    g = torch.Generator().manual_seed(1)
    for step in range(steps):
        x, y = torch.randn(32, 5, generator=g), torch.randn(32, 3, generator=g)
        optimizer.zero_grad()
        out = net[:3](x) if step < frozen_until else net(x)
        ((out - y) ** 2).mean().backward()
        optimizer.step()
    return torch.cat([p.detach().flatten() for p in net.parameters()])


@pytest.mark.parametrize("fused", [False, True], ids=["single-tensor", "fused"])
def test_the_same_parameters_as_torch_optim_adam(fused):
    ours = _train(lambda p: Adam(p, lr=1e-2, weight_decay=1e-3, capturable=fused))
    theirs = _train(lambda p: torch.optim.Adam(p, lr=1e-2, weight_decay=1e-3, fused=True if fused else None))
    assert torch.equal(ours, theirs)

