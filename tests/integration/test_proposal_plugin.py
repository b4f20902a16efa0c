"""A proposal from outside the package runs through the pipeline: registered in a plugin module, chosen with
method.proposal=<its name>, recorded in results.json."""

import textwrap

import pytest

from bayessim_exp.inference.bayessim.proposals import PROPOSALS
from bayessim_exp.pipeline import Pipeline

pytestmark = pytest.mark.slow

# the smoke budget's 5-epoch models fail the guard, which would hand the prior on (method.on_guard=fallback)
# and leave round 2 simulating from it: warn hands round 1's posterior on
MECHANICS = ["debug=smoke", "logging.progress=false", "method.on_guard=warn"]

# A researcher's module: the previous posterior moment-matched to one Gaussian and widened (its covariance
# doubled), a safer SNPE-A proposal than the posterior itself. It touches nothing in the package.
PLUGIN = textwrap.dedent('''
    from bayessim_exp.distributions.mixture import GaussianMixture, TruncatedMixture
    from bayessim_exp.distributions.probit import ProbitPosterior
    from bayessim_exp.inference.bayessim.proposals import Proposal, moment_matched, register_proposal


    def widened(gaussian, factor=2.0):
        return GaussianMixture(gaussian.log_weights, gaussian.means, factor * gaussian.covs)


    @register_proposal
    class WideGaussian(Proposal):
        name = "wide_gaussian"
        pools_rounds = False  # SNPE-A divides by this proposal: train on its own draws only

        def from_posterior(self, posterior, inputs):
            if inputs.probit is not None:  # the model is fitted in probit space: a Gaussian there
                return ProbitPosterior(widened(moment_matched(posterior.in_probit_space(), seed=inputs.seed)),
                                       inputs.probit)
            matched = moment_matched(posterior, seed=inputs.seed)
            return TruncatedMixture(widened(matched), inputs.prior.low, inputs.prior.high, seed=inputs.seed)
''')


def test_a_proposal_from_outside_the_package(compose, tmp_path, monkeypatch):
    (tmp_path / "mylab_proposal.py").write_text(PLUGIN)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(PROPOSALS, "wide_gaussian", None)  # removed again after the test, whatever registers it
    cfg = compose(MECHANICS + ["plugins=[mylab_proposal]", "method.proposal=wide_gaussian"])
    results = Pipeline(cfg, tmp_path / "run").run()
    assert [r["proposal"] for r in results["rounds"]] == ["prior", "wide_gaussian"]
    last = results["rounds"][-1]
    assert last["train_set_size"] == results["rounds"][0]["train_set_size"]  # round 2's simulations only
    assert last["log_prob_gain"] > 0
