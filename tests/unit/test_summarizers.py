"""Summarizers against known answers: indices, lagged correlations, signature algebra, masking."""

from __future__ import annotations

import pysiglib
import pysiglib.torch_api as siglib
import pytest
import torch

from bayessim_exp import registry
from bayessim_exp.errors import ConfigError
from bayessim_exp.sim.trajectories import Trajectories
from bayessim_exp.summarizers import tensor_algebra
from bayessim_exp.summarizers.signature import signature_path

ALL = [
    ("start", {"steps": 3}), ("waypoints", {"steps": 3}), ("corr", {}), ("corrdiff", {}),
    ("signatory", {}), ("signatory", {"log_signature": True, "lead_lag": True, "basepoint": True}),
    ("signatory", {"backend": "torch", "log_signature": True}), ("learned", {"time_points": 4}),
    ("learned", {"time_points": 4, "architecture": "mlp"}),
]


def build(name: str, **params):
    return registry.build("summarizer", {"name": name, **params})


def make_traj(states: torch.Tensor, actions: torch.Tensor, valid: torch.Tensor | None = None) -> Trajectories:
    n, t = actions.shape[:2]
    if valid is None:
        valid = torch.ones(n, t, dtype=torch.bool)
    return Trajectories(states, actions, torch.zeros(n, t, dtype=states.dtype), valid,
                        torch.zeros(n, dtype=torch.bool), 0.05)


def random_traj(n=5, horizon=12, s=3, a=2, seed=0, dtype=torch.float32) -> Trajectories:
    g = torch.Generator().manual_seed(seed)
    return make_traj(torch.randn(n, horizon + 1, s, generator=g, dtype=dtype),
                     torch.randn(n, horizon, a, generator=g, dtype=dtype))


def terminated(traj: Trajectories, steps: list[int]) -> Trajectories:
    """The same rollouts with row i ending after steps[i] valid steps, as the simulator stores them."""
    valid = torch.arange(traj.horizon)[None] < torch.tensor(steps)[:, None]
    states, actions = traj.states.clone(), traj.actions * valid[..., None]
    for i, n in enumerate(steps):
        states[i, n + 1:] = states[i, n]
    return make_traj(states, actions, valid)


# --- start / waypoints ---------------------------------------------------------------------

def test_waypoints_and_start_pick_the_right_time_indices():
    horizon, s = 10, 2
    t = torch.arange(horizon + 1, dtype=torch.float32)
    states = torch.stack([t, -t], -1)[None]  # state at time t is (t, -t)
    actions = (100 + t[:horizon])[None, :, None]
    out = build("waypoints", steps=5)(make_traj(states, actions))
    # linspace(0, 10, 5) = 0, 2.5, 5, 7.5, 10 rounded half to even; the last action clamps to T-1
    assert out[0, : 5 * s].reshape(5, s)[:, 0].tolist() == [0, 2, 5, 8, 10]
    assert out[0, 5 * s:].tolist() == [100, 102, 105, 108, 109]
    out = build("start", steps=4)(make_traj(states, actions))
    assert out[0, : 4 * s].reshape(4, s)[:, 0].tolist() == [0, 1, 2, 3]


# --- corr / corrdiff -----------------------------------------------------------------------

@pytest.mark.parametrize("name", ["corr", "corrdiff"])
def test_correlation_with_a_delayed_copy_peaks_at_the_delay(name):
    horizon, delay, lags = 300, 3, 6
    g = torch.Generator().manual_seed(1)
    a = torch.randn(1, horizon, 1, generator=g, dtype=torch.float64)
    delayed = torch.cat([torch.randn(1, delay, 1, generator=g, dtype=torch.float64), a[:, : horizon - delay]], 1)
    if name == "corr":  # s[t] = a[t - delay]
        states = torch.cat([delayed, torch.zeros(1, 1, 1, dtype=torch.float64)], 1)
    else:  # s[t+1] - s[t] = a[t - delay]
        states = torch.cat([torch.zeros(1, 1, 1, dtype=torch.float64), delayed.cumsum(1)], 1)
    out = build(name, lags=lags)(make_traj(states, a))
    cross = out[0, : lags + 1]
    assert int(cross.argmax()) == delay
    # an exact copy over n - delay of the n steps: the normalised sum is close to (n - delay) / (n - 1)
    assert cross[delay].item() == pytest.approx((horizon - delay) / (horizon - 1), abs=0.02)
    assert cross[[i for i in range(lags + 1) if i != delay]].abs().max() < 0.2


def test_corr_at_lag_zero_is_pearson_and_moments_are_the_channels():
    traj = random_traj(n=3, horizon=40, s=2, a=2, dtype=torch.float64)
    out = build("corr", lags=0)(traj)
    s_feats, a = traj.states[:, :-1], traj.actions
    for i in range(3):
        full = torch.corrcoef(torch.cat([s_feats[i], a[i]], 1).T)
        assert torch.allclose(out[i, :4].reshape(2, 2), full[:2, 2:], atol=1e-12)
        expected = torch.cat([s_feats[i].mean(0), s_feats[i].std(0), a[i].mean(0), a[i].std(0)])
        assert torch.allclose(out[i, 4:], expected, atol=1e-12)


# --- masking and finiteness (every summarizer) ---------------------------------------------

@pytest.mark.parametrize("name,params", ALL)
def test_steps_after_termination_do_not_change_the_summary(name, params):
    traj = terminated(random_traj(n=3), [12, 7, 4])
    summarizer = build(name, **params)
    reference = summarizer(traj)
    garbage = traj.states.clone(), traj.actions.clone()
    for i, n in enumerate([12, 7, 4]):
        garbage[0][i, n + 1:] = 1e3
        garbage[1][i, n:] = -1e3
    assert torch.allclose(summarizer(make_traj(*garbage, traj.valid)), reference)


@pytest.mark.parametrize("name,params", [p for p in ALL if p[0] in ("corr", "corrdiff", "signatory")])
def test_a_terminated_trajectory_summarises_like_its_valid_part(name, params):
    if name == "signatory":  # the time channel is scaled by the full horizon, so compare without it
        params = {**params, "time_augment": False}
    traj = random_traj(n=1, horizon=12)
    summarizer = build(name, lags=2) if name != "signatory" else build(name, **params)
    ended = summarizer(terminated(traj, [7]))
    assert torch.allclose(ended, summarizer(traj.truncate(7)), atol=1e-5)


def test_signatory_time_stops_when_the_episode_ends():
    steps = [12, 7, 0]
    out = build("signatory", depth=2)(terminated(random_traj(n=3, horizon=12), steps))
    # the first level-1 term is the time channel's total increment
    assert torch.allclose(out[:, 0], torch.tensor(steps) / 12.0)


@pytest.mark.parametrize("name,params", ALL)
def test_summaries_are_finite_with_constant_channels_and_very_short_episodes(name, params):
    traj = random_traj(n=4, dtype=torch.float64)
    traj.states[0, :, 1] = 1000.0  # constant state channel
    traj.actions[1] = 0.5  # constant actions
    traj = terminated(traj, [12, 12, 1, 0])
    states = traj.states.clone().requires_grad_()
    summarizer = build(name, **params)
    out = summarizer(make_traj(states, traj.actions, traj.valid))
    assert out.shape == (4, summarizer.output_dim(3, 2, 12))
    assert torch.isfinite(out).all()
    if out.requires_grad:
        out.sum().backward()
        assert torch.isfinite(states.grad).all()
    if name.startswith("corr"):  # the constant channel standardises to zero correlation, std 0
        cross = out[0, : 3 * 2 * 3].reshape(3, 3, 2)
        assert cross[:, 1].abs().max() == 0
        assert out[0, 18 + 3 + 1] == 0


# --- signatures ----------------------------------------------------------------------------

def levels(flat: torch.Tensor, dim: int, depth: int) -> list[torch.Tensor]:
    sizes = [dim**k for k in range(1, depth + 1)]
    return [torch.ones_like(flat[:, :1])] + list(torch.split(flat, sizes, 1))


def test_signature_of_a_straight_line_is_the_tensor_exponential_of_its_increment():
    g = torch.Generator().manual_seed(2)
    start, delta = torch.randn(3, 4, generator=g, dtype=torch.float64), torch.randn(3, 4, generator=g, dtype=torch.float64)
    # collinear points at uneven times along the segment
    fractions = torch.tensor([0.0, 0.1, 0.15, 0.6, 1.0], dtype=torch.float64)
    path = start[:, None] + fractions[None, :, None] * delta[:, None]
    expected = torch.cat([
        delta,
        torch.einsum("ni,nj->nij", delta, delta).flatten(1) / 2,
        torch.einsum("ni,nj,nk->nijk", delta, delta, delta).flatten(1) / 6,
    ], 1)
    assert torch.allclose(siglib.sig(path, 3), expected, atol=1e-12)
    assert torch.allclose(tensor_algebra.signature_features(path, 3, False), expected, atol=1e-12)


def test_chens_identity_signature_of_a_concatenation_is_the_tensor_product():
    dim, depth = 3, 4
    g = torch.Generator().manual_seed(3)
    first = torch.randn(2, 6, dim, generator=g, dtype=torch.float64)
    second = torch.cat([first[:, -1:], torch.randn(2, 5, dim, generator=g, dtype=torch.float64)], 1)
    whole = torch.cat([first, second[:, 1:]], 1)
    product = tensor_algebra.multiply(levels(siglib.sig(first, depth), dim, depth),
                                      levels(siglib.sig(second, depth), dim, depth))
    assert torch.allclose(siglib.sig(whole, depth), tensor_algebra.flatten(product), atol=1e-10)
    # and the identity fails for paths that do not join: the test can tell
    shifted = torch.cat([first, second[:, 1:] + 1.0], 1)
    assert not torch.allclose(siglib.sig(shifted, depth), tensor_algebra.flatten(product), atol=1e-3)


def test_signature_is_invariant_under_time_reparameterisation():
    dim, depth = 3, 3
    g = torch.Generator().manual_seed(4)
    path = torch.randn(2, 6, dim, generator=g, dtype=torch.float64)
    # the same curve traversed at another speed: extra points inside segments, and pauses
    points = []
    for i in range(5):
        for f in (0.0, 0.3, 0.3, 0.9):
            points.append(path[:, i] + f * (path[:, i + 1] - path[:, i]))
    points.append(path[:, 5])
    slower = torch.stack(points, 1)
    assert torch.allclose(siglib.sig(slower, depth), siglib.sig(path, depth), atol=1e-10)


@pytest.mark.parametrize("log_signature", [False, True])
def test_signatory_ignores_pauses_without_time_and_sees_them_with_time(log_signature):
    traj = random_traj(n=2, horizon=6)
    # every step taken twice over, as if the system paused at each state with its action held
    states = traj.states.repeat_interleave(2, 1)
    action_at = torch.arange(2 * 6 + 1).div(2, rounding_mode="floor").clamp(max=5)
    paused = make_traj(states, traj.actions[:, action_at])
    for time_augment, same in ((False, True), (True, False)):
        s = build("signatory", depth=3, time_augment=time_augment, log_signature=log_signature)
        assert torch.allclose(s(paused), s(traj), atol=1e-5) is same


@pytest.mark.parametrize("params", [{}, {"log_signature": True}, {"lead_lag": True, "basepoint": True},
                                    {"lead_lag": True, "log_signature": True, "time_augment": False}])
def test_pysiglib_and_the_plain_torch_reference_agree(params):
    traj = random_traj(n=4, horizon=8, s=2, a=1, dtype=torch.float64)
    fast = build("signatory", depth=3, **params)
    reference = build("signatory", depth=3, backend="torch", **params)
    out = fast(traj)
    assert out.shape == (4, fast.output_dim(2, 1, 8))
    assert torch.allclose(out, reference(traj), atol=1e-10)


def test_lead_lag_path_matches_pysiglib_and_lyndon_words_match_its_basis():
    traj = random_traj(n=2, horizon=5, s=2, a=1, dtype=torch.float64)
    plain = signature_path(traj, time_augment=False, lead_lag=False, basepoint=False)
    lead_lag = signature_path(traj, time_augment=False, lead_lag=True, basepoint=False)
    assert torch.allclose(siglib.sig(lead_lag, 3), siglib.sig(plain, 3, lead_lag=True), atol=1e-10)
    for dim, depth in ((2, 4), (7, 3)):
        assert tensor_algebra.lyndon_words(dim, depth) == [tuple(w) for w in pysiglib.lyndon_words(dim, depth)]


@pytest.mark.parametrize("log_signature", [False, True])
def test_signatory_gradcheck_float64(log_signature):
    traj = random_traj(n=2, horizon=4, s=2, a=1, dtype=torch.float64)
    s = build("signatory", depth=3, log_signature=log_signature, lead_lag=log_signature)

    def summary(states, actions):
        return s(make_traj(states, actions, traj.valid))

    inputs = (traj.states.clone().requires_grad_(), traj.actions.clone().requires_grad_())
    assert torch.autograd.gradcheck(summary, inputs, eps=1e-6, atol=1e-6)


# --- learned -------------------------------------------------------------------------------

@pytest.mark.parametrize("architecture", ["conv", "mlp"])
def test_learned_embedding_trains_jointly_with_the_mdnn(architecture):
    traj = random_traj(n=200, horizon=12, s=3, a=2, seed=5)
    theta = traj.states[:, -1, :2]  # something the trajectory determines
    summarizer = build("learned", time_points=6, architecture=architecture, embedding_dim=4)
    x = summarizer(traj)
    assert x.shape == (200, summarizer.output_dim(3, 2, 12))
    model = registry.build("model", {"name": "mdnn", "components": 2, "hidden": [16], "max_epochs": 3},
                           theta_dim=2, x_dim=x.shape[1], embedding=summarizer.embedding)
    model.fit(theta, x, seed=0)  # the first fit re-initialises every layer, so compare from here
    before = [p.detach().clone() for p in summarizer.embedding.parameters()]
    model.fit(theta, x, seed=1)  # fine-tuning: only backpropagation moves the weights now
    after = list(summarizer.embedding.parameters())
    assert len(after) == len(before) > 0
    assert all(not torch.equal(b, a) for b, a in zip(before, after))
    assert model.conditional(x[0]).dim == 2


# --- configuration errors, before any simulation ------------------------------------------

@pytest.mark.parametrize("name,params,horizon,message", [
    ("signatory", {"depth": 0}, 10, "depth"),
    ("signatory", {"backend": "signatory"}, 10, "backend"),
    ("start", {"steps": 11}, 10, "exceeds"),
    ("waypoints", {"steps": 11}, 10, "exceeds"),
    ("corr", {"lags": 10}, 10, "shorter"),
    ("corrdiff", {"lags": -1}, 10, "lags"),
    ("learned", {"time_points": 12}, 10, "time_points"),
    ("learned", {"architecture": "rnn"}, 10, "architecture"),
])
def test_bad_configuration_is_a_clear_error(name, params, horizon, message):
    with pytest.raises(ConfigError, match=message):
        build(name, **params).check(horizon)


def test_output_dims_are_explicit():
    assert build("corr", lags=2).output_dim(3, 2, 50) == 3 * 2 * 3 + 2 * 5
    # path [time, 3 states, 2 actions]: 6 + 36 + 216
    assert build("signatory", depth=3).output_dim(3, 2, 50) == 258
    assert build("signatory", depth=3, lead_lag=True, log_signature=True).output_dim(3, 2, 50) == \
        pysiglib.log_sig_length(11, 3)


@pytest.mark.parametrize("name", ["start", "waypoints", "corr", "corrdiff", "signatory", "learned"])
def test_every_shipped_yaml_builds_and_matches_its_output_dim(compose, pendulum, name):
    summarizer = registry.build("summarizer", compose([f"summarizer={name}"]).summarizer)
    summarizer.check(50)
    traj = random_traj(n=3, horizon=50, s=pendulum.obs_dim, a=pendulum.action_dim)
    assert summarizer(traj).shape == (3, summarizer.output_dim(pendulum.obs_dim, pendulum.action_dim, 50))
