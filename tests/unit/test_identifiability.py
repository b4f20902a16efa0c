"""The identifiability report against a linear-Gaussian simulator whose answers are known in closed form."""

import pytest
import torch

from bayessim_exp.diagnostics.identifiability import linear_read, sensitivity

NAMES = ["direct", "unseen", "sum_a", "sum_b"]


def simulate(n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """u ~ N(0, I_4); x = [u_direct + e (unit noise), u_a + u_b + 0.1 e', two pure-noise columns, a constant]:
    R^2 of E[u_direct | x] = 1 / (1 + 1) = 0.5, of E[u_a | x] = E[u_b | x] = c = 1 / 2.01 (s = u_a + u_b + 0.1 e');
    u_unseen leaves no trace; the errors u_a - c s and u_b - c s correlate at -c / (1 - c) = -1 / 1.01."""
    g = torch.Generator().manual_seed(seed)
    u = torch.randn(n, 4, generator=g, dtype=torch.float64)
    noise = torch.randn(n, 4, generator=g, dtype=torch.float64)
    x = torch.stack([u[:, 0] + noise[:, 0], u[:, 2] + u[:, 3] + 0.1 * noise[:, 1], noise[:, 2], noise[:, 3],
                     torch.ones(n, dtype=torch.float64)], 1)
    return x, u


def test_r2_matches_the_closed_form():
    x, u = simulate(20_000, 0)
    report = linear_read(x, u, NAMES)
    r2 = report["r2"]
    assert report["pairs"] == 4000
    assert r2["direct"] == pytest.approx(0.5, abs=0.03)
    assert r2["sum_a"] == pytest.approx(1 / 2.01, abs=0.03) and r2["sum_b"] == pytest.approx(1 / 2.01, abs=0.03)
    assert abs(r2["unseen"]) < 0.01


def test_a_pair_identified_only_through_its_sum_trades_off():
    x, u = simulate(20_000, 1)
    trade_offs = linear_read(x, u, NAMES)["trade_offs"]
    assert [t["pair"] for t in trade_offs] == [["sum_a", "sum_b"]]
    assert trade_offs[0]["correlation"] < -0.95


def test_summaries_that_never_vary_identify_nothing():
    x, u = simulate(1000, 2)
    report = linear_read(torch.ones_like(x), u, NAMES)
    assert all(abs(v) < 0.02 for v in report["r2"].values())


def test_local_sensitivity_of_a_known_linear_response():
    """x = A u at every trajectory (a kept and a diverged one): the effect of u_i is column i of A, so its RMS is
    exact; a zero column does nothing; two parallel columns are collinear (cosine 1, index beyond any bound)."""
    A = torch.tensor([[2.0, 0.0, 1.0, 1.0], [0.0, 0.0, 3.0, 3.0 + 1e-9]], dtype=torch.float64)

    def summaries_at(points):
        x = (points @ A.T)[:, None].expand(-1, 2, -1).clone()
        return x, torch.tensor([True, False])

    local = sensitivity(summaries_at, torch.tensor([0.3, -1.0, 0.5, 2.0], dtype=torch.float64),
                        torch.tensor([1.0, 2.0], dtype=torch.float64), NAMES)
    assert local["trajectories"] == 1
    assert local["rms"]["direct"] == pytest.approx((2.0**2 / 2) ** 0.5)
    assert local["rms"]["sum_a"] == pytest.approx(((1.0 + 1.5**2) / 2) ** 0.5)
    assert local["no_effect"] == ["unseen"]
    assert [c["pair"] for c in local["collinear"]] == [["sum_a", "sum_b"]]
    assert local["collinear"][0]["cosine"] == pytest.approx(1.0) and local["collinear"][0]["index"] > 1e3
