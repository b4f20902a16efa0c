"""models/mixture_nll.py: the head's loss with its written-out gradient against autograd through the
matrix form (U assembled by the head, `mixture_nll`)."""

import pytest
import torch

from bayessim_exp.models.mdnn import MixtureHead
from bayessim_exp.models.mixture_nll import HeadNLL, mixture_nll

CASES = [(1, 1, True), (2, 5, True), (4, 3, True), (2, 5, False), (5, 2, False)]  # dim, components, full


def _head(dim, components, full, spread=1.0):
    """(the mixture's layout, the network's last layer writing it, features, targets)"""
    torch.manual_seed(dim * 10 + components)
    head = MixtureHead(dim, components, full)
    layer = torch.nn.Linear(6, head.width).double()
    with torch.no_grad():
        layer.weight.mul_(spread)
    return head, layer, torch.randn(40, 6, dtype=torch.float64), torch.randn(40, dim, dtype=torch.float64)


@pytest.mark.parametrize("spread", [1.0, 40.0], ids=["inside", "clamped"])  # 40: log-diagonals beyond +-12
@pytest.mark.parametrize("dim,components,full", CASES)
def test_loss_and_gradients_match_autograd_through_the_matrix_form(dim, components, full, spread):
    head, layer, h, theta = _head(dim, components, full, spread)
    sizes = [components, components * dim, components * dim, components * head.n_off]
    log_diag = torch.split(layer(h), sizes, -1)[2]
    gradients = []
    for loss_of in (lambda t: mixture_nll(*head(layer(h)), t), lambda t: head.nll(layer(h), t)):
        layer.zero_grad()
        t = theta.clone().requires_grad_()
        loss = loss_of(t)
        (loss * torch.linspace(0.5, 1.5, len(loss), dtype=torch.float64)).sum().backward()
        gradients.append([loss.detach(), t.grad, *(p.grad.clone() for p in layer.parameters())])
    for ours, reference in zip(gradients[1], gradients[0]):
        assert torch.allclose(ours, reference, rtol=1e-9, atol=1e-9)
    assert (log_diag.abs() > 12).any() == (spread > 1)


@pytest.mark.parametrize("dim,components,full", CASES)
def test_gradcheck(dim, components, full):
    head, layer, h, theta = _head(dim, components, full)
    out = layer(h)[:8].detach().requires_grad_()
    t = theta[:8].clone().requires_grad_()
    assert torch.autograd.gradcheck(lambda o, x: HeadNLL.apply(o, x, head.upper_rows, head.upper_cols, components),
                                    (out, t))


def test_a_far_component_does_not_cancel_the_loss_in_single_precision():
    """Component 0 sits 1e3 standard deviations away (its log-density about -5e5): the loss is the
    near component's, to float32's precision."""
    head, layer, h, theta = _head(2, 3, True)
    with torch.no_grad():
        layer.bias[3:5] = 1e3  # component 0's mean
    reference = mixture_nll(*head(layer(h)), theta)
    ours = head.nll(layer.float()(h.float()), theta.float()).double()
    assert torch.allclose(ours, reference, rtol=1e-5, atol=1e-4)
    assert reference.abs().max() < 100
