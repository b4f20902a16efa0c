"""The report's calibration section: where the truth lies in the final posterior, over the jobs of a
known-truth study (sweeps/calibration.yaml: each seed's surrogate parameters drawn from the prior;
sweeps/nominal.yaml: the MJCF's values, a few moved, what real robots look like; results.json's `truth_source`).
Only for a configuration whose jobs hold at least two different truths (results.json's `true_params`): seeds
repeated at one truth (real.truth=task, the default) say how a run varies, not whether its posteriors are calibrated.

Read from each round record's `truth` (diagnostics/scoring.py): `hpd_level`, the share of posterior draws
denser than the truth (inside the level-L region iff below L; null, zero density, counts as outside), and
`marginal_rank` per parameter (an SBC rank over the number of draws: uniform over truths drawn from the
prior when the pipeline is calibrated). Per configuration: the share of truths inside the 50 % and 90 %
regions with a Clopper-Pearson 95 % interval, per round; the gain at the truth (quartiles, share above zero,
count of zero densities); how often the guard failed or handed on another distribution (the prior among them) and
how often the
mismatch flag fired, in the final round and in any round; in how many rounds the real data lay outside the
training simulations (diagnostics/extrapolation.py: with truths from the prior, its false alarms); and one PNG of SBC rank histograms per parameter
of the final round, each with the binomial 99 % band of a uniform histogram; where every truth was drawn from the
prior, per parameter the KS p-value and C2ST accuracy of those ranks against uniform ones (sbc.py).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
from scipy import stats

from . import sbc
from .jobs import Job

LEVELS = (0.5, 0.9)
BINS = 10
MAX_PARAMETERS = 16  # histograms drawn per configuration; the others are counted in the figure's title
CONFIDENCE = 0.95
_SOURCES = {"prior": "drawn from the prior", "nominal": "nominal: the MJCF's values, a few moved",
            "corner": "corner: every parameter 1-5 % inside one of its prior's tails",
            "task": "the task's real_params", "None": "recorded with the data"}


@dataclasses.dataclass
class Calibration:
    jobs: int  # finished jobs that know their truth
    truths: int  # different truths among them
    left_out: int  # finished jobs without a truth (a fixed or unknown one)
    inside: dict[float, list[tuple[int, int]]]  # level -> per round (truths inside, jobs with that round)
    # level -> (truths inside, jobs) in each job's final round: runs that added rounds (an escape under way,
    # method.escape_rounds) end later than the others
    final_inside: dict[float, tuple[int, int]]
    # the same in the model's probit space (results.json's `hpd_level_probit`), over the jobs that record it
    final_inside_probit: dict[float, tuple[int, int]]
    gains: list[float | None]  # final round's gain at the truth
    guard_failed_final: int
    guard_failed_any: int
    handed_on_other: int  # final rounds whose guard handed on another distribution (fallback)
    handed_on_prior: int  # final rounds that handed on the prior: domain randomization gains nothing
    sources: list[str]  # where the jobs' truths came from (real.truth), as results.json says
    flagged_final: int
    flagged_any: int
    outside_rounds: tuple[int, int]  # rounds whose real data lay outside the training simulations, rounds checked
    ranks: dict[str, list[float]]  # parameter -> final round's marginal ranks
    uniformity: dict[str, tuple[float, float | None]] | None  # parameter -> (KS p, C2ST); None: truths not from the prior


def clopper_pearson(k: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """The exact binomial interval of a share k / n."""
    alpha = 1 - confidence
    low = 0.0 if k == 0 else float(stats.beta.ppf(alpha / 2, k, n - k + 1))
    high = 1.0 if k == n else float(stats.beta.ppf(1 - alpha / 2, k + 1, n - k))
    return low, high


def _known(jobs: list[Job]) -> list[Job]:
    return [j for j in jobs if j.results and j.results["rounds"] and j.results["rounds"][-1].get("truth")]


def _truth(job: Job) -> tuple:
    values = job.results.get("true_params") or {}
    return tuple(sorted((name, round(float(v), 9)) for name, v in values.items()))


def fixed_truth(jobs: list[Job]) -> str | None:
    """Why a configuration gets no calibration section although its jobs know their truth (all at one truth);
    None otherwise."""
    known = _known(jobs)
    if not known or len({_truth(j) for j in known}) > 1:
        return None
    sources = sorted({str(j.results.get("truth_source")) for j in known})
    return (f"{len(known)} job(s) at one truth (real.truth={'/'.join(sources)}): no calibration section; a known-truth "
            "study varies the truth per seed (real.truth=prior: sweeps/calibration.yaml, or nominal)")


def calibration(jobs: list[Job]) -> Calibration | None:
    """The section's numbers over finished jobs whose rounds carry `truth`; None when none does or when they all
    share one truth."""
    known = _known(jobs)
    truths = len({_truth(j) for j in known})
    if truths < 2:
        return None
    rounds = max(len(j.results["rounds"]) for j in known)
    inside: dict[float, list[tuple[int, int]]] = {level: [] for level in LEVELS}
    for r in range(rounds):
        levels = [j.results["rounds"][r]["truth"]["hpd_level"] for j in known
                  if len(j.results["rounds"]) > r and j.results["rounds"][r].get("truth")]
        for level in LEVELS:
            inside[level].append((sum(v is not None and v < level for v in levels), len(levels)))
    finals = [j.results["rounds"][-1] for j in known]
    final_levels = [f["truth"]["hpd_level"] for f in finals if f.get("truth")]
    final_inside = {level: (sum(v is not None and v < level for v in final_levels), len(final_levels))
                    for level in LEVELS}
    probit_levels = [f["truth"]["hpd_level_probit"] for f in finals
                     if f.get("truth") and f["truth"].get("hpd_level_probit") is not None]
    final_inside_probit = {level: (sum(v < level for v in probit_levels), len(probit_levels)) for level in LEVELS}
    ranks: dict[str, list[float]] = {}
    for final in finals:
        for name, value in final["truth"]["marginal_rank"].items():
            ranks.setdefault(name, []).append(value)

    def guard_failed(record: dict) -> bool:
        guard = record.get("guard") or {}
        return bool(guard.get("failed", not guard.get("ok", True)))

    def flagged(record: dict) -> bool:
        return bool((record.get("mismatch") or {}).get("flagged"))

    checked = [r["extrapolation"] for j in known for r in j.results["rounds"] if r.get("extrapolation")]
    sources = sorted({str(j.results.get("truth_source")) for j in known})

    return Calibration(
        jobs=len(known), truths=truths, left_out=sum(1 for j in jobs if j.results) - len(known), inside=inside,
        final_inside=final_inside, final_inside_probit=final_inside_probit,
        gains=[f.get("log_prob_gain") for f in finals],
        guard_failed_final=sum(guard_failed(f) for f in finals),
        guard_failed_any=sum(any(guard_failed(r) for r in j.results["rounds"]) for j in known),
        handed_on_other=sum((f.get("guard") or {}).get("action") in ("fallback", "provisional") for f in finals),
        handed_on_prior=sum((f.get("guard") or {}).get("handed_on") == "the prior" for f in finals),
        sources=sources,
        flagged_final=sum(flagged(f) for f in finals),
        flagged_any=sum(any(flagged(r) for r in j.results["rounds"]) for j in known),
        outside_rounds=(sum(bool(e["flagged"]) for e in checked), len(checked)), ranks=ranks,
        # uniform ranks are what a calibrated pipeline gives over truths drawn from the prior, and only there
        uniformity=sbc.uniformity(ranks) if sources == ["prior"] else None)


def share_text(k: int, n: int) -> str:
    """k / n with its Clopper-Pearson interval, as the report and docs/results.md write a share."""
    low, high = clopper_pearson(k, n)
    return f"{k}/{n} = {k / n:.2f} [{low:.2f}, {high:.2f}]"


def markdown(config: str, c: Calibration, figure: Path | None) -> list[str]:
    gains = [g for g in c.gains if g is not None and math.isfinite(g)]
    zero = len(c.gains) - len(gains)
    quartiles = np.percentile(gains, [25, 50, 75]) if gains else [math.nan] * 3
    final = c.final_inside
    lines = [f"### `{config}`", "",
             (f"{c.jobs} truths" if c.truths == c.jobs else f"{c.jobs} jobs at {c.truths} different truths")
             + f" ({', '.join(_SOURCES.get(s, s) for s in c.sources)})"
             + (f" ({c.left_out} finished jobs without a known truth left out)" if c.left_out else "")
             + ". Share of truths inside the final posterior's highest-density regions (Clopper-Pearson "
             f"{CONFIDENCE:.0%} interval): " + "; ".join(f"{level:.0%} region {share_text(*final[level])}"
                                                           for level in LEVELS) + ".", "",
             "| round | " + " | ".join(f"inside {level:.0%} region" for level in LEVELS) + " |",
             "|---|" + "---|" * len(LEVELS)]
    for r in range(len(c.inside[LEVELS[0]])):
        lines.append(f"| {r + 1} | " + " | ".join(share_text(*c.inside[level][r]) for level in LEVELS) + " |")
    if c.final_inside_probit[LEVELS[0]][1]:
        lines += ["", "The final regions in the model's probit space, where its spread is calibrated and the guard "
                  "reads them (the probit map's Jacobian makes them other sets of the same mass: docs/statistics.md, "
                  "'Which space the regions live in'): "
                  + "; ".join(f"{level:.0%} region {share_text(*c.final_inside_probit[level])}" for level in LEVELS)
                  + "."]
    lines += ["",
              f"Log-density gain at the truth, final round: quartiles {quartiles[0]:+.2f} / {quartiles[1]:+.2f} / "
              f"{quartiles[2]:+.2f} nats; above zero for {sum(g > 0 for g in gains)} of {len(c.gains)}"
              + (f"; **{zero} final posterior(s) put zero density at the truth**" if zero else "") + ".",
              f"Guard failed: final round {c.guard_failed_final} of {c.jobs}, any round {c.guard_failed_any}; "
              f"the final round handed on another distribution (fallback) in {c.handed_on_other}, the prior in "
              f"{c.handed_on_prior}. "
              f"Mismatch flagged: final round {c.flagged_final} of {c.jobs}, any round {c.flagged_any}. "
              "Real data outside the training simulations: "
              + (f"{share_text(*c.outside_rounds)} of the rounds checked (the guard fails such a round unless the "
                 "replay widening stands in for the check: docs/statistics.md, 'Many parameters')."
                 if c.outside_rounds[1] else "not checked.")]
    if figure is not None:
        lines += ["", f"![SBC ranks of `{config}`]({figure.name})"]
    lines += [""] + uniformity_markdown(c)
    return lines + [""]


def uniformity_markdown(c: Calibration) -> list[str]:
    if c.uniformity is None:
        return ["SBC uniformity tests: not computed, the truths were not drawn from the prior (only over prior draws "
                "are a calibrated pipeline's ranks uniform)."]
    lines = [f"Uniformity of the final round's SBC ranks over {c.jobs} truths, as sbi's `check_sbc` reports it: the "
             "Kolmogorov-Smirnov p-value against U(0, 1) (small: not uniform; with D parameters expect the smallest "
             f"of D uniform p-values near 1/(D+1)) and the C2ST accuracy telling the ranks from uniform draws (0.5: "
             f"indistinguishable; a chance classifier's spread is about {0.5 / math.sqrt(2 * c.jobs):.2f} here)"
             + ("; **fewer than 100 truths**: both tests have little power" if c.jobs < 100 else "")
             + (f"; no C2ST below {sbc.MIN_C2ST} truths" if c.jobs < sbc.MIN_C2ST else "") + ".", "",
             "| parameter | KS p-value | C2ST accuracy |", "|---|---|---|"]
    for name, (p, accuracy) in c.uniformity.items():
        lines.append(f"| {name} | {p:.3g} | {'–' if accuracy is None else f'{accuracy:.2f}'} |")
    return lines


SBC_CSV_HEADER = ["configuration", "parameter", "truths", "ks_pvalue", "c2st_accuracy"]


def sbc_rows(config: str, c: Calibration) -> list[list]:
    return [[config, name, c.jobs, f"{p:.4g}", "" if accuracy is None else f"{accuracy:.4f}"]
            for name, (p, accuracy) in (c.uniformity or {}).items()]


def csv_row(config: str, c: Calibration) -> list:
    row: list = [config, c.jobs, c.truths]
    for level in LEVELS:
        k, n = c.final_inside[level]
        row += [k, n, f"{k / n:.4f}", *(f"{v:.4f}" for v in clopper_pearson(k, n))]
    gains = [g for g in c.gains if g is not None and math.isfinite(g)]
    row += [sum(g > 0 for g in gains), len(c.gains) - len(gains), c.guard_failed_final, c.guard_failed_any,
            c.handed_on_other, c.handed_on_prior, c.flagged_final, c.flagged_any, *c.outside_rounds]
    return row + [k for level in LEVELS for k in c.final_inside_probit[level]]


CSV_HEADER = ["configuration", "truths", "different_truths",
              *(f"{name}_{level:g}" for level in LEVELS for name in ("inside", "rounds_of", "share", "ci_low", "ci_high")),
              "gain_above_zero", "zero_density", "guard_failed_final", "guard_failed_any", "fallback_final", "prior_final",
              "flagged_final", "flagged_any", "outside_rounds", "rounds_checked",
              *(f"{name}_{level:g}" for level in LEVELS for name in ("inside_probit", "rounds_of_probit"))]


def rank_figure(c: Calibration, title: str, path: Path) -> Path:
    """One histogram of the final round's marginal ranks per parameter, with the grey 99 % band a uniform
    histogram of as many ranks stays in, bin by bin."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(c.ranks)[:MAX_PARAMETERS]
    cols = min(4, len(names))
    rows = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.0 * cols, 2.4 * rows), squeeze=False)
    for ax, name in zip(axes.flat, names):
        values = np.asarray(c.ranks[name])
        counts, edges = np.histogram(values, bins=BINS, range=(0.0, 1.0))
        low, high = stats.binom.ppf([0.005, 0.995], len(values), 1 / BINS)
        ax.axhspan(low, high, color="0.85")
        ax.axhline(len(values) / BINS, color="0.5", lw=1)
        ax.bar(edges[:-1], counts, width=1 / BINS, align="edge", color="C0", edgecolor="white")
        ax.set_title(name, fontsize=9)
        ax.set_xlim(0, 1)
    for ax in list(axes.flat)[len(names):]:
        ax.axis("off")
    more = len(c.ranks) - len(names)
    fig.suptitle(f"{title}: SBC ranks of the truth, final round ({c.jobs} truths)"
                 + (f"; {more} more parameter(s) not shown" if more else ""), fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
