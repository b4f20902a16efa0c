"""Real data from a pendulum nobody on this project wrote (bayessim_exp/testing/independent_pendulum.py: the
rigid-rod ODE by RK4, not our MJCF): the posterior covers our model's best fit, and data the model cannot
represent are either still covered or flagged as a model mismatch."""

import numpy as np
import pytest
import torch

from bayessim_exp import api, registry
from bayessim_exp.__main__ import summary_lines
from bayessim_exp.inference.bayessim.combination import combine
from bayessim_exp.policies import RandomPolicy
from bayessim_exp.real import load_trajectories, save_trajectories
from bayessim_exp.sim.pool import SimulatorPool
from bayessim_exp.testing import independent_pendulum
from bayessim_exp.testing.independent_pendulum import best_fit, best_fits, hpd_level

pytestmark = pytest.mark.slow

HIDDEN = [(0.7, 0.35), (1.0, 0.5), (1.6, 0.7), (0.8, 0.6)]
FOREIGN = [(0.7, 0.35), (1.0, 0.5), (1.6, 0.7), (1.3, 0.85)]  # benchmarks/foreign_dynamics.py's settings
# (truth, the two control steps whose angular-velocity reading a sensor glitch moves)
GLITCHES = [((1.3, 0.6), (1, 6)), ((0.8, 0.9), (3, 11)), ((1.7, 0.45), (2, 15)), ((1.0, 0.75), (4, 9))]


@pytest.fixture(scope="module")
def fitted():
    """One MDNN (conf/model/mdnn.yaml) on 10,000 prior simulations of 20 steps: round 1 of the default run."""
    torch.manual_seed(0)
    cfg = api.compose([])
    task = registry.build("task", cfg.task)
    prior = registry.build("prior", cfg.prior, spec=task.spec)
    summarizer = registry.build("summarizer", cfg.summarizer)
    sims = SimulatorPool(registry.build("sim", cfg.sim), task, chunk=4096)
    theta = prior.sample((10_000,)).double()
    traj = sims.rollout(theta, RandomPolicy(1, 0), 20, seed=0)
    model = registry.build("model", cfg.model, theta_dim=2, x_dim=summarizer.output_dim(3, 1, 20))
    model.fit(theta.float(), summarizer(traj), seed=0, label="independent pendulum")
    return task, prior, summarizer, sims, model


def test_well_specified_data_put_the_best_fit_inside_the_90_percent_region(fitted):
    """Acceptance 1: 4 hidden parameter sets x 1 and 5 trajectories; the best fit of our model inside the
    90 % HPD region in at least 85 % of the cases (7 of 8), and a positive log-density gain at it in all."""
    task, prior, summarizer, sims, model = fitted
    levels, gains = [], []
    for k, (mass, length) in enumerate(HIDDEN):
        data = independent_pendulum.simulate(mass, length, 5, 20, seed=100 + k)
        full = load_trajectories(data, task, 20, "independent pendulum")
        for n, fit in zip((1, 5), best_fits(sims, full, 20, [1, 5])):
            real = full.select(torch.arange(n))
            post, _ = combine("dispersion", [model.conditional(x) for x in summarizer(real)], prior)
            t = torch.as_tensor(fit)[None]
            levels.append(hpd_level(post, fit))
            gains.append(float(post.log_prob(t) - prior.log_prob(t)))
    assert sum(level < 0.9 for level in levels) >= 7, levels
    assert min(gains) > 0, gains


@pytest.mark.parametrize("variant", [{"damping": 0.05}, {"shape": "bob"}, {"angle_offset": np.pi}],
                         ids=["unmodelled_damping", "mass_in_a_bob", "angle_from_hanging_down"])
def test_data_the_model_cannot_represent_are_covered_or_flagged(tmp_path, variant, compose):
    """Acceptance 2: the run keeps the best fit of our model inside its 90 % region or flags a mismatch."""
    data = independent_pendulum.simulate(1.0, 0.5, 5, 20, seed=3, **variant)
    path = tmp_path / "robot.npz"
    np.savez(path, **data)
    out = tmp_path / "run"
    results = api.run(["real=file", f"real.path={path}", "collect.trajectories=5000", "collect.horizon=20",
                       "rounds=2", "diagnostics.predictive_sims=0", "logging.progress=false"], out_dir=out)
    run = api.load_run(out)
    cfg = compose()
    task = registry.build("task", cfg.task)
    real = load_trajectories(data, task, 20, "independent pendulum")
    fit = best_fit(SimulatorPool(registry.build("sim", cfg.sim), task, chunk=4096), real, 20)
    covered = hpd_level(run.posterior(), fit) < 0.9
    flagged = results["rounds"][-1]["mismatch"]["flagged"]
    assert covered or flagged, results["rounds"][-1]["mismatch"]
    if "angle_offset" in variant:  # a wrong convention is never something to cover quietly
        assert flagged


def test_logs_driven_by_another_controller_are_replayed_and_covered(tmp_path, compose):
    """The issue's case: five trajectories of our own pendulum at 1.6 kg, 0.7 m driven by sines (as a robot's
    excitation log), not by the random collect policy. real=file replays their starts and actions (policy=replay,
    its default), so the simulations are driven as the data were: the truth lies inside the final posterior's
    90 % region, no mismatch is flagged, and the posterior knows much more than the prior there: +4.2 nats at this
    budget, where the random collect policy's simulations (policy=random) gave +1.3 with the truth outside their
    90 % region (b74b05b, dev box; +6.7 and +4.0 before the product's temperature was fitted by coverage)."""
    path = tmp_path / "sine.npz"
    task = registry.build("task", compose(["sim=native"]).task)
    rng = np.random.default_rng(200)
    state = task.reset_state(rng, 5)
    actions = torch.as_tensor(independent_pendulum.excitation("sine", 5, 50, rng), dtype=torch.float32)
    pool = SimulatorPool(registry.build("sim", {"name": "native"}), task, chunk=4096)
    from bayessim_exp.policies import OpenLoopPolicy
    from bayessim_exp.real import save_trajectories

    traj = pool.rollout(np.tile([1.6, 0.7], (5, 1)), OpenLoopPolicy(actions), 50, seed=0, state=state)
    save_trajectories(path, traj, np.array([1.6, 0.7]), ["mass", "length"])
    out = tmp_path / "run"
    results = api.run(["real=file", f"real.path={path}", "collect.trajectories=3000", "rounds=2",
                       "diagnostics.predictive_sims=0", "logging.progress=false"], out_dir=out)
    last = results["rounds"][-1]
    assert results["policy"] == "replay"
    assert last["truth"]["hpd_level"] < 0.9 and not last["mismatch"]["flagged"], (last["truth"], last["mismatch"])
    assert last["log_prob_gain"] > 3.0


def test_another_integrator_s_data_keep_the_truth_and_most_of_the_information(tmp_path):
    """Issue 44's model error with a known answer: one trajectory of the same rod physics integrated by RK4 with 50
    substeps at each of four hidden parameter sets. Our simulator's own integrator (implicitfast at 10 ms) differs
    most in the early steps, which the summaries weigh most, so simulations with it alone read that error as a
    parameter shift; simulations alternating it with RK4 (method.integrators=auto for recorded data, on native
    MuJoCo) hold the truth inside the 90 % region in at least 3 of the 4 and keep a median gain of +6 nats at it.
    With the model's integrator alone (method.integrators=[model], or MJX: sim=auto on a GPU machine) the test fails
    (docs/statistics.md, 'Integrators as a nuisance')."""
    levels, gains = [], []
    for k, (mass, length) in enumerate(FOREIGN):
        path = tmp_path / f"rk4_{k}.npz"
        np.savez(path, **independent_pendulum.simulate(mass, length, 1, 50, seed=101))
        results = api.run(["real=file", f"real.path={path}", "sim=native", "collect.trajectories=3000", "rounds=2",
                           "diagnostics.predictive_sims=0", "logging.progress=false", "logging.figures=false"],
                          out_dir=tmp_path / f"run_{k}")
        levels.append(results["rounds"][-1]["truth"]["hpd_level"])
        gains.append(results["rounds"][-1]["log_prob_gain"])
    assert results["integrators"] == ["model", "RK4"]  # what the run says it simulated with
    assert summary_lines(results, tmp_path)[-1] == ("  simulated with the integrators model, RK4 alternating "
                                                   "(method.integrators)")
    assert sum(level < 0.9 for level in levels) >= 3, levels
    assert float(np.median(gains)) >= 6.0, gains


def glitched_runs(tmp_path, offset: float, overrides=()) -> list[dict]:
    """One 20-step trajectory of our own pendulum at each GLITCHES truth, its angular velocity at the two steps read
    `offset` times that reading's spread over 500 prior draws too high, run as recorded data (3,000 simulations of 20
    steps a round, the default three rounds: the error model read in round r is simulated in round r + 1): each run's
    results."""
    cfg = api.compose([])
    task = registry.build("task", cfg.task)
    prior = registry.build("prior", cfg.prior, spec=task.spec)
    pool = SimulatorPool(registry.build("sim", {"name": "native"}), task, chunk=4096)
    theta = prior.sample((500,), generator=torch.Generator().manual_seed(0)).numpy()
    spread = pool.rollout(theta, RandomPolicy(1, 1), 20, 1).states[:, :, 2].double().std(0)
    runs = []
    for k, (truth, steps) in enumerate(GLITCHES):
        real = pool.rollout(np.array([truth]), RandomPolicy(1, 7 + k), 20, 7 + k)
        for step in steps:
            real.states[:, step, 2] += offset * spread[step]
        path = tmp_path / f"glitch_{k}.npz"
        save_trajectories(path, real, truth, task.spec.names)
        runs.append(api.run(["real=file", f"real.path={path}", "sim=native", "collect.trajectories=3000",
                             "collect.horizon=20", "diagnostics.predictive_sims=0",
                             "logging.progress=false", "logging.figures=false", *overrides],
                            out_dir=tmp_path / f"run_{k}"))
    return runs


def test_a_sensor_glitch_in_two_readings_keeps_the_truth_and_most_of_the_information(tmp_path):
    """Issue 44's known summary bias: our own pendulum's data (well specified), two of whose 80 summary features
    (angular-velocity readings at two steps) carry a known offset of 0.2 of their spread over the prior. The replays
    of round 1's posterior leave those readings unexplained; round 2's simulated summaries get noise of that size
    there (method.summary_error=replays), so q reads the parameters from the 78 exact features: the truth inside the
    90 % region in at least 3 of the 4 and a median gain of at least +6 nats at it. Without the error model
    (method.summary_error=none) the replays' tempering widens every direction and the median gain falls to +1.5
    (docs/statistics.md, 'A summary error model'). A glitch read once stays in the model: a round trained with its
    noise can read nothing, and until the model was kept then, round 3 lost it (SummaryError.carried). At 0.2 the
    replays of a run can miss the glitch in every round (1 of 32 runs over seeds 0-7 on the development machine):
    read in at least 3 of the 4."""
    runs = glitched_runs(tmp_path, 0.2)
    levels = [run["rounds"][-1]["truth"]["hpd_level"] for run in runs]
    gains = [run["rounds"][-1]["log_prob_gain"] for run in runs]
    # per run and round: are the glitched readings among the features with noise? Once they are, in every later round
    held = [[{3 * step + 2 for step in steps} <= set((r["summary_error"] or {"features": []})["features"])
             for r in run["rounds"]] for run, (_, steps) in zip(runs, GLITCHES)]
    assert all(rounds == sorted(rounds) for rounds in held), held
    assert sum(rounds[-1] for rounds in held) >= 3, held
    assert sum(level < 0.9 for level in levels) >= 3, levels
    assert float(np.median(gains)) >= 6.0, gains


if __name__ == "__main__":  # the glitch test's runs with other offsets or settings, e.g. method.summary_error=none
    import argparse
    import json
    import tempfile
    from pathlib import Path

    ap = argparse.ArgumentParser(description="glitched_runs: each run's truth level and gain at the truth")
    ap.add_argument("--offset", type=float, default=0.2)
    ap.add_argument("overrides", nargs="*")
    args = ap.parse_args()
    for run in glitched_runs(Path(tempfile.mkdtemp(prefix="glitch_")), args.offset, args.overrides):
        last = run["rounds"][-1]
        print(json.dumps({"offset": args.offset, "overrides": args.overrides, "level": last["truth"]["hpd_level"],
                          "gain": last["log_prob_gain"], "summary_error": last["summary_error"],
                          "temperatures": [r["temperature"] for r in run["rounds"]]}), flush=True)


def test_a_pendulum_outside_the_prior_s_box_hands_on_the_prior_not_a_posterior_on_its_corner(tmp_path, compose):
    """A log of our own pendulum at 0.1 kg and 0.1 m, where the prior's box is [0.5, 2] x [0.25, 1]: no parameter in
    the box reproduces it, and the honest answer is the prior with the warning that the box does not hold the robot.
    The network's posterior there is an extrapolation collapsed on the box's corner (mass 0.5 +- 0, length 0.871 +-
    3e-5 at this seed); its replay widening stopped at its floor with the replays still too narrow, so the guard reads
    the distance from the training simulations that the widening otherwise stands in for. Before that, round 1
    passed and its point mass was handed on."""
    task = registry.build("task", compose(["sim=native"]).task)
    rng = np.random.default_rng(100)
    state = task.reset_state(rng, 1)
    from bayessim_exp.policies import OpenLoopPolicy

    actions = torch.as_tensor(independent_pendulum.excitation("random", 1, 50, rng), dtype=torch.float32)
    pool = SimulatorPool(registry.build("sim", {"name": "native"}), task, chunk=4096)
    traj = pool.rollout(np.array([[0.1, 0.1]]), OpenLoopPolicy(actions), 50, seed=0, state=state)
    path = tmp_path / "outside.npz"
    save_trajectories(path, traj, np.array([0.1, 0.1]), ["mass", "length"])
    results = api.run(["real=file", f"real.path={path}", "sim=native", "collect.trajectories=2000", "rounds=2",
                       "logging.progress=false", "logging.figures=false"], out_dir=tmp_path / "run")
    assert results["handed_on"]["round"] == 0, results["handed_on"]
    assert results["rounds"][0]["guard"]["near_real_data_only"], results["rounds"][0]["guard"]
    for r in results["rounds"]:
        assert r["guard"]["failed"] and any("outside the training simulations' range" in w for w in r["guard"]["warnings"]), r["guard"]
