"""MDNN recovers the closed-form posterior of a linear-Gaussian simulator; an ensemble is its members' average."""

import math

import pytest
import torch

from bayessim_exp import api
from bayessim_exp.distributions.mixture import GaussianMixture
from bayessim_exp.errors import TrainingError


def linear_gaussian(n, seed=0, noise=0.3):
    g = torch.Generator().manual_seed(seed)
    A = torch.tensor([[1.0, 0.5], [0.0, 1.0], [1.0, -1.0]])
    theta = torch.randn(n, 2, generator=g)
    x = theta @ A.T + noise * torch.randn(n, 3, generator=g)
    return theta, x, A, noise


# the ensemble of three: over 10 s, make test only
@pytest.mark.parametrize("covariance, ensemble", [("full", 1), ("diagonal", 1),
                                                 pytest.param("diagonal", 3, marks=pytest.mark.slow)])
def test_mdnn_matches_analytic_gaussian_posterior(covariance, ensemble):
    theta, x, A, noise = linear_gaussian(12_000)
    fitted = api.fit_posterior_model("mdnn", theta, x, components=2, covariance=covariance, max_epochs=60,
                                     patience=10, hidden=[64, 64], ensemble=ensemble)
    x_obs = torch.tensor([0.5, 0.2, -0.4])
    cov = torch.linalg.inv(torch.eye(2) + A.T @ A / noise**2)
    mean = cov @ (A.T @ x_obs / noise**2)
    post = fitted.posterior(x_obs)
    # tolerances: a few percent of the prior scale (1.0) on the mean, 20 % on the variances
    torch.testing.assert_close(post.mean.float(), mean, atol=0.05, rtol=0)
    torch.testing.assert_close(post.covariance.diagonal().float(), cov.diagonal(), rtol=0.2, atol=0)
    if covariance == "full":
        torch.testing.assert_close(post.covariance[0, 1].float(), cov[0, 1], atol=0.01, rtol=0)


@pytest.mark.slow  # a known-answer study taking over 10 s: make test, not make test-fast
def test_several_observations_combine_to_the_n_observation_posterior():
    theta, x, A, noise = linear_gaussian(12_000, seed=1)
    fitted = api.fit_posterior_model("mdnn", theta, x, components=1, max_epochs=60, patience=10, hidden=[64, 64])
    # with a flat prior the product of per-observation posteriors is the n-observation posterior;
    # here the prior is N(0, I): prod_i p(theta|x_i) / p(theta)^(n-1) -> compare after that division
    xs = torch.tensor([[0.5, 0.2, -0.4], [0.3, 0.1, 0.0], [0.8, 0.4, -0.2]])
    post = fitted.posterior(xs)
    n = len(xs)
    precision = torch.linalg.inv(post.covariance.float()) - (n - 1) * torch.eye(2)
    cov_ratio = torch.linalg.inv(precision)
    mean_ratio = cov_ratio @ (torch.linalg.inv(post.covariance.float()) @ post.mean.float())
    cov = torch.linalg.inv(torch.eye(2) + n * A.T @ A / noise**2)
    mean = cov @ (A.T @ xs.sum(0) / noise**2)
    torch.testing.assert_close(mean_ratio, mean, atol=0.05, rtol=0)
    torch.testing.assert_close(cov_ratio.diagonal(), cov.diagonal(), rtol=0.25, atol=0)


def test_nan_in_training_names_the_round_and_step():
    theta, x, _, _ = linear_gaussian(500)
    fitted = api.fit_posterior_model("mdnn", theta, x, max_epochs=2)
    bad = x.clone()
    bad[7, 1] = float("nan")
    with pytest.raises(TrainingError, match=r"round 3: (validation )?loss became nan at epoch 0, step \d+"):
        fitted.model.fit(theta, bad, seed=0, label="round 3")


def test_embedding_is_trained_jointly():
    theta, x, _, _ = linear_gaussian(2000)
    embedding = torch.nn.Linear(3, 4)
    from bayessim_exp import registry

    model = registry.build("model", {"name": "mdnn", "components": 1, "max_epochs": 3, "hidden": [16]},
                           theta_dim=2, x_dim=3, embedding=embedding)
    model.fit(theta, x, seed=0)
    before = embedding.weight.detach().clone()
    model.fit(theta, x, seed=1)  # fine-tuning moves the embedding with the rest of the network
    assert not torch.allclose(before, embedding.weight)
    assert any(k.startswith("embedding.") for k in model.state_dict()["net"])  # saved with the model


def test_ensemble_is_the_equally_weighted_average_of_different_members():
    theta, x, _, _ = linear_gaussian(2000)
    fitted = api.fit_posterior_model("mdnn", theta, x, components=2, ensemble=3, max_epochs=3, hidden=[16])
    model, x_obs = fitted.model, torch.tensor([0.5, 0.2, -0.4])
    post = model.conditional(x_obs)
    assert post.num_components == 6
    members = []
    networks = model.members
    for m in range(3):  # each member alone, as a one-network MDNN would condition (same spread factors)
        h = model.inputs(x_obs[None])
        for i, (weight, bias) in enumerate(zip(networks.weights, networks.biases)):  # the member's own layers
            h = torch.nn.functional.linear(h, weight[m].T, bias[m, 0])
            h = torch.relu(h) if i < len(networks.weights) - 1 else h
        logits, means, U = model.head(h)
        U_inv = torch.linalg.inv(model.spread.scale_factors(U)[0].double())
        members.append(GaussianMixture(logits[0], means[0], U_inv @ U_inv.transpose(-1, -2))
                       .affine(model.theta_norm.shift, model.theta_norm.scale))
    points = torch.randn(50, 2, dtype=torch.float64)
    densities = torch.stack([m.log_prob(points) for m in members])
    torch.testing.assert_close(post.log_prob(points), torch.logsumexp(densities, 0) - math.log(3))
    assert not torch.allclose(members[0].mean, members[1].mean)  # initialised apart


def test_a_state_saved_with_one_network_per_member_loads_into_the_stacked_members():
    """States saved before the members' layers were stacked (a ModuleList of nn.Sequential members, the head's layer
    at `<m>.<i>.out`) still condition as they did."""
    theta, x, _, _ = linear_gaussian(600)
    model = api.fit_posterior_model("mdnn", theta, x, components=2, ensemble=2, max_epochs=2, hidden=[8, 8]).model
    state = model.state_dict()
    net = {k: v for k, v in state["net"].items() if not k.startswith("members.")}
    for m in range(2):
        for i, index in enumerate(["0", "2", "4.out"]):  # Linear, ReLU, Linear, ReLU, head
            net[f"members.{m}.{index}.weight"] = state["net"][f"members.weights.{i}"][m].T.clone()
            net[f"members.{m}.{index}.bias"] = state["net"][f"members.biases.{i}"][m, 0].clone()
    fresh = api.fit_posterior_model("mdnn", theta, x, components=2, ensemble=2, max_epochs=1, hidden=[8, 8],
                                    seed=1).model
    fresh.load_state_dict({**state, "net": net})
    points = torch.randn(20, 2, dtype=torch.float64)
    x_obs = torch.tensor([0.5, 0.2, -0.4])
    torch.testing.assert_close(fresh.conditional(x_obs).log_prob(points), model.conditional(x_obs).log_prob(points))
