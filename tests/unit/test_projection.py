"""Regression summaries: the ridge projection recovers a linear map, its training inputs are
out-of-fold, and a model with projected inputs fits and conditions."""

import pytest
import torch

from bayessim_exp.models.projection import RidgeProjection, RidgeSystem
from bayessim_exp.registry import build


def _linear_data(n: int = 3000, features: int = 40, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    theta = torch.randn(n, 3, generator=g)
    mixing = torch.randn(3, features, generator=g)
    x = theta @ mixing + 0.1 * torch.randn(n, features, generator=g)
    return theta, x


def test_projection_predicts_linearly_decodable_parameters():
    theta, x = _linear_data()
    proj = RidgeProjection(x.shape[1], 3)
    out_of_fold = proj.fit(x, theta, seed=0)
    assert out_of_fold.shape == theta.shape
    assert (proj(x) - theta).pow(2).mean() < 1e-3
    assert (out_of_fold - theta).pow(2).mean() < 1e-3


def test_out_of_fold_predictions_are_no_better_than_chance_on_noise():
    """Pure-noise summaries: in-sample predictions fit the noise, out-of-fold ones must not."""
    g = torch.Generator().manual_seed(1)
    theta, x = torch.randn(400, 2, generator=g), torch.randn(400, 300, generator=g)
    proj = RidgeProjection(300, 2)
    out_of_fold = proj.fit(x, theta, seed=0)
    corr = torch.stack([torch.corrcoef(torch.stack([out_of_fold[:, d], theta[:, d]]))[0, 1] for d in range(2)])
    assert corr.abs().max() < 0.2


def test_mdnn_with_projected_inputs_fits_and_conditions():
    torch.set_num_threads(1)
    theta, x = _linear_data(n=2000)
    model = build("model", {"name": "mdnn", "components": 1, "hidden": [16], "max_epochs": 30, "project_inputs": True},
                  theta_dim=3, x_dim=x.shape[1])
    model.fit(theta, x, seed=0)
    q = model.conditional(x[0])
    assert torch.allclose(q.mean.float(), theta[0], atol=0.25)  # prior std 1; 30 epochs of a small network
    state = model.state_dict()
    assert "projection.weight" in state["net"]


def _ridge_reference(z, y, penalty):
    """argmin |y - z w - b|^2 + penalty |w|^2 by least squares on rows augmented with sqrt(penalty) I."""
    n, f = z.shape
    design = torch.cat([z, torch.ones(n, 1, dtype=z.dtype)], 1)
    augmented = torch.cat([design, torch.cat([penalty ** 0.5 * torch.eye(f, dtype=z.dtype), torch.zeros(f, 1, dtype=z.dtype)], 1)])
    targets = torch.cat([y, torch.zeros(f, y.shape[1], dtype=y.dtype)])
    return torch.linalg.lstsq(augmented, targets).solution


@pytest.mark.parametrize("features", [20, 300])  # fewer features than rows (primal), more (dual)
def test_ridge_system_matches_least_squares_reference(features):
    g = torch.Generator().manual_seed(features)
    z = torch.randn(120, features, generator=g, dtype=torch.float64) + 3.0  # offset: the intercept matters
    y = torch.randn(120, 2, generator=g, dtype=torch.float64) + torch.tensor([5.0, -2.0], dtype=torch.float64)
    system = RidgeSystem(z, y)
    assert system.dual == (features > 120)
    leave_out = torch.arange(120) % 5 == 0
    for penalty in (1e-2, 1.0, 100.0):
        assert torch.allclose(system.solve(penalty), _ridge_reference(z, y, penalty), atol=1e-8)
        assert torch.allclose(system.solve(penalty, leave_out), _ridge_reference(z[~leave_out], y[~leave_out], penalty),
                              atol=1e-8)
