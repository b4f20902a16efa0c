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



def test_a_finite_loss_with_a_non_finite_gradient_is_named():
    """sqrt at 0: the loss is 0, its gradient infinite; training stops at the first such step."""
    from types import SimpleNamespace

    from bayessim_exp.errors import TrainingError
    from bayessim_exp.models.adam_steps import EagerAdamSteps

    net = torch.nn.Linear(2, 1)
    nll = lambda theta, x: torch.sqrt((net(x) - net(x).detach()).abs()).squeeze(-1)  # noqa: E731
    cfg = SimpleNamespace(batch_size=8, lr=1e-3, weight_decay=0.0)
    steps = EagerAdamSteps(net, nll, torch.zeros(32, 1), torch.randn(32, 2), cfg, "round 2", rows_per_epoch=32)
    steps.epoch(torch.arange(32))
    with pytest.raises(TrainingError, match=r"round 2: non-finite gradient at epoch 0, step 1$"):
        steps.finish_epoch(0, steps.validation_loss(torch.arange(8)))
