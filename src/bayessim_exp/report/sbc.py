"""Are a parameter's SBC ranks uniform? The two numbers sbi's `check_sbc` reports per parameter.

- `ks_pvalue`: the Kolmogorov-Smirnov test of the ranks (shares of posterior draws below the truth, in [0, 1])
  against U(0, 1). Over truths drawn from the prior a calibrated pipeline's p-values are themselves uniform: a
  small one says the ranks are not (too narrow posteriors pile ranks at 0 and 1, biased ones on one side).
- `c2st_accuracy`: a classifier two-sample test: the cross-validated accuracy of a classifier telling the ranks
  from as many U(0, 1) draws. 0.5 is chance (indistinguishable, as calibrated ranks are); 1 means every rank
  is told apart. sbi's classifier is an MLP; ranks are one number each, where k nearest neighbours
  (k ~ sqrt(2n), majority vote) separate any density from the uniform one just as well and need nothing
  beyond numpy. The uniform draws are seeded and the accuracy averaged over `repetitions` fresh draws and fold
  splits, so a report is reproducible and its C2ST less noisy than one split.

With n truths the accuracy of a chance classifier has a standard deviation of about 0.5 / sqrt(2n) (0.035 at 100
truths): sbi asks for at least 100 truths, and below MIN_C2ST none is computed.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

FOLDS = 5
REPETITIONS = 5
MIN_C2ST = 10  # truths: below, each fold would hold one or two ranks


def ks_pvalue(ranks) -> float:
    return float(stats.kstest(np.asarray(ranks, float), "uniform").pvalue)


def c2st_accuracy(ranks, seed: int = 0, repetitions: int = REPETITIONS, folds: int = FOLDS) -> float | None:
    """Cross-validated k-NN accuracy between the ranks and U(0, 1) draws (0.5: indistinguishable); None below
    MIN_C2ST ranks."""
    ranks = np.asarray(ranks, float)
    n = len(ranks)
    if n < MIN_C2ST:
        return None
    rng = np.random.default_rng(seed)
    labels = np.r_[np.ones(n, bool), np.zeros(n, bool)]
    k = max(1, int(math.sqrt(2 * n)) | 1)  # odd: no tied votes
    correct = 0
    for _ in range(repetitions):
        x = np.r_[ranks, rng.uniform(size=n)]
        fold = np.empty(2 * n, int)  # stratified: each fold holds as many ranks as uniform draws
        fold[:n] = rng.permutation(n) % folds
        fold[n:] = rng.permutation(n) % folds
        for f in range(folds):
            test, train = fold == f, fold != f
            distance = np.abs(x[test, None] - x[None, train])
            nearest = np.argpartition(distance, k - 1, axis=1)[:, :k]
            vote = labels[train][nearest].sum(1) * 2 > k
            correct += int((vote == labels[test]).sum())
    return correct / (repetitions * 2 * n)


def uniformity(ranks: dict[str, list[float]], seed: int = 0) -> dict[str, tuple[float, float | None]]:
    """Per parameter (KS p-value, C2ST accuracy)."""
    return {name: (ks_pvalue(values), c2st_accuracy(values, seed)) for name, values in ranks.items()}
