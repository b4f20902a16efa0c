"""The sweep report over a hand-made sweep dir: statuses, per-configuration intervals, and failures listed, not fatal."""

import csv
import json
import os
import re
import time

import pytest
import yaml

from bayessim_exp.report.__main__ import main
from bayessim_exp.report.build import build_report
from bayessim_exp.report.metrics import interval


def results(seed, gains, summarizer="start", coverage=0.5, rl_return=None):
    rl = None if rl_return is None else {"mean": rl_return, "min": rl_return - 1, "max": rl_return + 1, "std": 1.0}
    rounds = [{"round": r + 1, "log_prob_gain": g, "posterior_std": {"a": 0.1, "b": 0.4}, "prior_std": {"a": 0.2, "b": 0.4},
               "coverage": {"hpd": {"0.5": coverage}}, "surrogate_real_return": rl,
               "seconds": {"collect": 1.0, "fit": 2.0}} for r, g in enumerate(gains)]
    return {"task": "Pendulum", "model": "mdnn", "summarizer": summarizer, "policy": "random", "seed": seed,
            "param_names": ["a", "b"], "true_params": {"a": 1.0, "b": 2.0}, "rounds": rounds}


def make_job(sweep, name, overrides, rounds=2, result=None, error=None, raw=None):
    job = sweep / name
    (job / ".hydra").mkdir(parents=True)
    (job / ".hydra" / "overrides.yaml").write_text(yaml.safe_dump(overrides))
    (job / ".hydra" / "config.yaml").write_text(yaml.safe_dump({"rounds": rounds, "seed": 0}))
    if result is not None:
        (job / "results.json").write_text(json.dumps(result))
    if raw is not None:
        (job / "results.json").write_text(raw)
    if error is not None:
        (job / "error.txt").write_text(error)
    return job


@pytest.fixture
def sweep(tmp_path):
    sweep = tmp_path / "sweep"
    common = ["debug=smoke"]
    make_job(sweep, "0_start_s0", ["summarizer=start", "seed=0", *common], result=results(0, [0.5, 1.0], coverage=0.4))
    make_job(sweep, "1_start_s1", ["summarizer=start", "seed=1", *common], result=results(1, [1.5, 3.0], coverage=0.9))
    make_job(sweep, "2_way_s0", ["summarizer=waypoints", "seed=0", *common],
             result=results(0, [0.2, 2.0], "waypoints", rl_return=-200.0))
    make_job(sweep, "3_way_s1", ["summarizer=waypoints", "seed=1", *common], result=results(1, [0.1], "waypoints"))
    make_job(sweep, "4_corr_s0", ["summarizer=corr", "seed=0", *common],
             error="Traceback (most recent call last):\n  ...\nPosteriorError: round 1: no mass in the box\n")
    make_job(sweep, "5_corr_s1", ["summarizer=corr", "seed=1", *common])
    make_job(sweep, "6_corr_s2", ["summarizer=corr", "seed=2", *common], raw="{not json")
    # failed once, then rerun to the end in the same dir: the newer results.json wins
    job = make_job(sweep, "7_way_s2", ["summarizer=waypoints", "seed=2", *common], error="killed\n")
    old = time.time() - 60
    os.utime(job / "error.txt", (old, old))
    (job / "results.json").write_text(json.dumps(results(2, [0.3, 1.0], "waypoints", rl_return=-100.0)))
    (sweep / ".submitit" / "12_0").mkdir(parents=True)  # launcher files are not jobs
    return sweep


def test_statuses_intervals_and_failures(sweep):
    report = build_report(sweep)
    status = {j.path.name: (j.status, j.problem) for j in report.jobs}
    assert [j.path.name for j in report.jobs] == [f"{k}_{n}" for k, n in enumerate(
        ["start_s0", "start_s1", "way_s0", "way_s1", "corr_s0", "corr_s1", "corr_s2", "way_s2"])]
    assert status["3_way_s1"] == ("unfinished", "1 of 2 rounds")
    assert status["4_corr_s0"] == ("failed", "PosteriorError: round 1: no mass in the box")
    assert status["5_corr_s1"] == ("unfinished", "no results.json")
    assert status["6_corr_s2"][0] == "failed" and "unreadable" in status["6_corr_s2"][1]
    assert status["7_way_s2"][0] == "finished"

    with (sweep / "report" / "summary.csv").open() as f:
        rows = {r["configuration"]: r for r in csv.DictReader(f)}
    assert set(rows) == {"summarizer=start", "summarizer=waypoints", "summarizer=corr"}  # debug=smoke is shared
    start = rows["summarizer=start"]
    # gains 1 and 3: mean 2, standard error 1, t(0.975, 1 dof) = 12.706
    assert (start["finished"], start["log_prob_gain_mean"], start["log_prob_gain_ci_low"],
            start["log_prob_gain_ci_high"]) == ("2", "2", "-10.7", "14.7")
    assert float(start["std_ratio_mean"]) == pytest.approx(0.75)
    assert float(start["coverage_hpd_0.5_ci_low"]) == 0.0 and float(start["coverage_hpd_0.5_ci_high"]) == 1.0
    assert float(start["wall_seconds_mean"]) == pytest.approx(6.0)
    assert start["surrogate_real_return_mean"] == ""  # no job of this configuration ran RL
    assert float(rows["summarizer=waypoints"]["surrogate_real_return_mean"]) == pytest.approx(-150.0)
    assert (rows["summarizer=corr"]["finished"], rows["summarizer=corr"]["failed"],
            rows["summarizer=corr"]["unfinished"]) == ("0", "2", "1")

    markdown = (sweep / "report" / "report.md").read_text()
    assert "8 jobs: 4 finished, 2 failed, 2 unfinished" in markdown
    assert "| summarizer=start | 2 | 2 [-10.7, 14.7] |" in markdown
    assert "`4_corr_s0`: failed: PosteriorError: round 1: no mass in the box" in markdown
    # the hand-made jobs have no run artifacts: their posteriors are listed as not drawn, the report goes on
    assert "Not drawn:" in markdown and len(report.figure_problems) == 2
    assert {p.name for p in report.figures} >= {"log_prob_gain.png", "std_ratio.png", "gain_by_round.png"}
    assert all(p.stat().st_size > 1000 for p in report.figures)


def test_cli_exit_codes(sweep, tmp_path, capsys):
    assert main([str(sweep), "--no-posteriors", "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "8 jobs: 4 finished, 2 failed, 2 unfinished" in out and "4_corr_s0" in out
    assert (tmp_path / "out" / "report.md").is_file()
    assert main([str(tmp_path / "nowhere")]) == 2
    (tmp_path / "empty").mkdir()
    assert main([str(tmp_path / "empty")]) == 2
    assert "no job dirs" in capsys.readouterr().err


def test_interval():
    assert interval([2.0]) == (2.0, pytest.approx(float("nan"), nan_ok=True), pytest.approx(float("nan"), nan_ok=True))
    mean, lo, hi = interval([1.0, 2.0, 3.0, None])
    assert mean == 2.0 and hi - mean == pytest.approx(4.302653 * 1.0 / 3 ** 0.5)
    assert interval([0.9, 1.0], bounds=(0.0, 1.0))[2] == 1.0


def test_a_job_with_a_null_gain_is_counted_and_named_not_averaged_away(tmp_path):
    """Three seeds, one of whose posteriors put zero density at the truth (results.json writes null): the mean
    is over the other two, says n = 2, and report.md and summary.csv name the job."""
    sweep = tmp_path / "sweep"
    for seed, gain in enumerate([1.0, None, 3.0]):
        make_job(sweep, f"{seed}_s{seed}", [f"seed={seed}"], result=results(seed, [0.5, gain]))
    build_report(sweep, posteriors=False)
    with (sweep / "report" / "summary.csv").open() as f:
        row = next(csv.DictReader(f))
    assert (row["finished"], row["log_prob_gain_mean"], row["log_prob_gain_n"]) == ("3", "2", "2")
    assert row["std_ratio_n"] == "3" and row["missing values"] == "log_prob_gain: 1_s1"
    markdown = (sweep / "report" / "report.md").read_text()
    assert "| all | 3 | 2 [-10.7, 14.7] (n = 2) |" in markdown
    assert "`all`, `log_prob_gain`: `1_s1`: **the final posterior put zero density at the truth**" in markdown


def truth_results(seed, levels, ranks, gain=1.0, guard_failed=False, flagged=False, outside=False, source="prior",
                  probit_level=None):
    """A known-truth job: one round record per HPD level of the truth (and `probit_level` in the model's probit
    space, None as for a posterior not defined there); `outside`: its last round's real data lay outside the
    training simulations. Its truth is the task's (seed 0's) unless drawn from the prior or nominal."""
    out = {**results(seed, [gain] * len(levels)), "truth_source": source}
    if source != "task":
        out["true_params"] = {"a": 1.0 + 0.01 * seed, "b": 2.0}
    for record, level in zip(out["rounds"], levels):
        record["truth"] = {"hpd_level": level, "marginal_rank": dict(zip(["a", "b"], ranks)),
                           "hpd_level_probit": probit_level}
        record["guard"] = {"ok": not guard_failed, "failed": guard_failed, "warnings": [],
                           "action": "fallback" if guard_failed else "none",
                           "handed_on": "the prior" if guard_failed else "round 2's posterior"}
        record["mismatch"] = {"flagged": flagged}
        record["extrapolation"] = {"flagged": [0] if outside and record is out["rounds"][-1] else []}
    return out


def test_the_calibration_section_counts_truths_inside_each_region_per_round(tmp_path):
    """100 truths at HPD levels 0.005, 0.015, ..., 0.995 (a calibrated pipeline's levels, evenly): 50 inside the
    50 % region and 90 inside the 90 % one, with their Clopper-Pearson intervals; round 1 at level 0.95 for all,
    none inside; one null level (zero density) counted as outside; guard and mismatch counts."""
    from scipy.stats import beta

    sweep = tmp_path / "sweep"
    for k in range(100):
        level = None if k == 0 else (k + 0.5) / 100
        make_job(sweep, f"{k}_s{k}", [f"seed={k}"], result=truth_results(
            k, [0.95, level], [(k + 0.5) / 100, 0.5], gain=None if k == 0 else 1.0,
            guard_failed=k < 3, flagged=k == 7, outside=k in (3, 4),
            probit_level=None if k >= 80 else (k + 0.5) / 80))  # 80 record it, 40 below 0.5 and 72 below 0.9
    make_job(sweep, "100_s100", ["seed=100"], result=results(100, [1.0, 1.0]))  # no truth recorded: left out
    build_report(sweep, posteriors=False)
    with (sweep / "report" / "calibration.csv").open() as f:
        row = next(csv.DictReader(f))
    # levels 0.015 .. 0.495 are below 0.5 (49 of them), 0.015 .. 0.895 below 0.9 (89); the null one is outside
    assert (row["truths"], row["inside_0.5"], row["inside_0.9"], row["rounds_of_0.9"]) == ("100", "49", "89", "100")
    assert float(row["ci_low_0.9"]) == pytest.approx(beta.ppf(0.025, 89, 12), abs=1e-4)
    assert float(row["ci_high_0.9"]) == pytest.approx(beta.ppf(0.975, 90, 11), abs=1e-4)
    assert (row["zero_density"], row["gain_above_zero"], row["guard_failed_final"], row["fallback_final"],
            row["prior_final"], row["flagged_final"], row["flagged_any"]) == ("1", "99", "3", "3", "3", "1", "1")
    assert (row["outside_rounds"], row["rounds_checked"]) == ("2", "200")
    assert (row["inside_probit_0.5"], row["rounds_of_probit_0.5"], row["inside_probit_0.9"]) == ("40", "80", "72")
    markdown = (sweep / "report" / "report.md").read_text()
    assert "100 truths (drawn from the prior) (1 finished jobs without a known truth left out)" in markdown
    assert "handed on another distribution (fallback) in 3, the prior in 3" in markdown
    assert "| 1 | 0/100 = 0.00 [0.00, 0.04] | 0/100 = 0.00 [0.00, 0.04] |" in markdown
    assert "90% region 89/100 = 0.89 [0.81, 0.94]" in markdown
    assert "**1 final posterior(s) put zero density at the truth**" in markdown
    assert "probit space, where its spread is calibrated" in markdown and "90% region 72/80 = 0.90" in markdown
    assert "Real data outside the training simulations: 2/200 = 0.01 [0.00, 0.04] of the rounds checked (the guard fails such a round unless" in markdown
    assert (sweep / "report" / "sbc_ranks_00.png").stat().st_size > 1000
    # a's ranks are evenly spread (uniform), b's all 0.5 (a posterior centred on every truth, too wide)
    with (sweep / "report" / "sbc.csv").open() as f:
        sbc = {r["parameter"]: r for r in csv.DictReader(f)}
    assert sbc["a"]["truths"] == "100" and float(sbc["a"]["ks_pvalue"]) > 0.99 and float(sbc["b"]["ks_pvalue"]) < 1e-20
    assert 0.4 < float(sbc["a"]["c2st_accuracy"]) < 0.6 and float(sbc["b"]["c2st_accuracy"]) > 0.9
    assert re.search(r"^\| a \| 1 \| 0\.[45]\d \|$", markdown, re.M)
    assert "as sbi's `check_sbc` reports it" in markdown and "fewer than 100 truths" not in markdown


def test_a_sweep_without_known_truths_has_no_calibration_section(sweep):
    build_report(sweep, posteriors=False)
    assert "Calibration" not in (sweep / "report" / "report.md").read_text()
    assert not (sweep / "report" / "calibration.csv").exists()


def truth_sweep(tmp_path, jobs: int, source: str):
    """A sweep of `jobs` known-truth jobs whose truths came from `source` (real.truth), reported: (dir, report.md)."""
    sweep = tmp_path / "sweep"
    for seed in range(jobs):
        make_job(sweep, f"{seed}_s{seed}", [f"seed={seed}"],
                 result=truth_results(seed, [0.3, 0.4], [0.2, 0.7], source=source))
    build_report(sweep, posteriors=False)
    return sweep, (sweep / "report" / "report.md").read_text()


def test_seeds_repeated_at_one_truth_get_no_calibration_section(tmp_path):
    """`--multirun seed=0,1` at the task's own truth: every job knows its truth, but it is the same one; the report
    says so instead of counting '2 truths' with a per-round table, SBC histograms and uniformity tests."""
    sweep, markdown = truth_sweep(tmp_path, 2, "task")
    assert "Calibration" not in markdown and "2 truths" not in markdown
    assert "`all`: 2 job(s) at one truth (real.truth=task): no calibration section" in markdown
    assert not any((sweep / "report" / name).exists() for name in ("calibration.csv", "sbc.csv", "sbc_ranks_00.png"))


def test_nominal_truths_get_the_section_without_uniformity_tests(tmp_path):
    """Truths at the MJCF's values, a few moved, vary but are not prior draws: their ranks need not be uniform."""
    sweep, markdown = truth_sweep(tmp_path, 12, "nominal")
    assert "## Calibration (known truths)" in markdown and "12 truths (nominal" in markdown
    assert "SBC uniformity tests: not computed, the truths were not drawn from the prior" in markdown
    assert "probit space" not in markdown  # no job recorded a probit-space level (results before it existed)
    assert (sweep / "report" / "calibration.csv").exists() and not (sweep / "report" / "sbc.csv").exists()


def test_ks_and_c2st_tell_calibrated_ranks_from_skewed_and_overconfident_ones():
    """Known answers over 40 studies of 100 truths each: ranks drawn uniform pass (KS p below 0.05 in about 5 %
    of studies, C2ST near 0.5), ranks of posteriors biased low (Beta(5, 1)) or too narrow (Beta(0.2, 0.2): ranks
    piled at 0 and 1) fail in every study; a Bayes classifier reaches 0.77 and 0.76 on these two."""
    import numpy as np

    from bayessim_exp.report.sbc import c2st_accuracy, ks_pvalue, uniformity

    rng = np.random.default_rng(1)
    uniform = [rng.uniform(size=100) for _ in range(40)]
    ks = [ks_pvalue(r) for r in uniform]
    c2st = [c2st_accuracy(r, seed=s) for s, r in enumerate(uniform)]
    assert sum(p < 0.05 for p in ks) <= 6  # binomial(40, 0.05): P(> 6) < 0.005
    assert abs(np.mean(c2st) - 0.5) < 0.03 and max(c2st) < 0.66
    for a, b in ((5.0, 1.0), (0.2, 0.2)):
        studies = [rng.beta(a, b, 100) for _ in range(40)]
        assert max(ks_pvalue(r) for r in studies) < 0.01
        accuracies = [c2st_accuracy(r, seed=s) for s, r in enumerate(studies)]
        assert min(accuracies) > 0.62 and np.mean(accuracies) > 0.7
    assert c2st_accuracy(uniform[0][:9]) is None  # too few truths for five folds
    assert uniformity({"x": list(uniform[0])}, seed=0)["x"] == (ks[0], c2st[0])


def test_tensorboard_hparams_compare_the_finished_jobs(sweep, capsys):
    """One experiment summary in the sweep dir, one session per finished job with its configuration and final
    metrics (what `tensorboard --logdir <sweep>` shows under HPARAMS); rewritten, not duplicated, by the report."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
    from tensorboard.plugins.hparams import metadata

    from bayessim_exp.report.hparams import write_hparams

    def hparams_of(directory):
        acc = EventAccumulator(str(directory)).Reload()
        return acc, acc.PluginTagToContent(metadata.PLUGIN_NAME)

    assert sorted(p.name for p in write_hparams(sweep)) == ["0_start_s0", "1_start_s1", "2_way_s0", "7_way_s2"]
    assert main([str(sweep), "--no-posteriors"]) == 0  # writes them again
    assert f"tensorboard --logdir {sweep}" in capsys.readouterr().out
    assert len(list(sweep.glob("*/events.out.tfevents.*.hparams"))) == 4
    assert len(list(sweep.glob("events.out.tfevents.*.hparams"))) == 1

    _, root = hparams_of(sweep)
    experiment = metadata.parse_experiment_plugin_data(root[metadata.EXPERIMENT_TAG])
    infos = {h.name: h for h in experiment.hparam_infos}
    assert {"task", "model", "summarizer", "seed", "real.truth", "debug", "configuration"} <= set(infos)
    assert [v.string_value for v in infos["summarizer"].domain_discrete.values] == ["start", "waypoints"]
    assert {m.name.tag for m in experiment.metric_infos} >= {"hparams/log_prob_gain", "hparams/surrogate_real_return"}

    acc, tags = hparams_of(sweep / "2_way_s0")
    start = metadata.parse_session_start_info_plugin_data(tags[metadata.SESSION_START_INFO_TAG])
    assert start.hparams["summarizer"].string_value == "waypoints" and start.hparams["seed"].number_value == 0
    assert start.hparams["configuration"].string_value == "summarizer=waypoints"
    assert metadata.EXPERIMENT_TAG not in tags
    assert [e.value for e in acc.Scalars("hparams/log_prob_gain")] == [2.0]
    assert [e.value for e in acc.Scalars("hparams/surrogate_real_return")] == [-200.0]
    assert not list((sweep / "3_way_s1").glob("*.hparams"))  # unfinished: no session


def test_the_final_share_reads_each_runs_own_last_round_and_a_run_killed_in_an_added_round_is_unfinished(tmp_path):
    """Ten runs of `rounds=2`: seven end there with the truth inside (level 0.3); two added a third round (an escape
    under way, results.json's rounds_planned) and end at level 0.3 after 0.95 in round 2; one was killed inside its
    added round. The final share is 9 of the 9 finished runs' last rounds, not round 3's 2 of 2; the killed run is
    left out as unfinished."""
    sweep = tmp_path / "sweep"
    for seed in range(10):
        added = seed >= 7
        levels = [0.5, 0.95, 0.3] if added and seed < 9 else [0.5, 0.95] if added else [0.5, 0.3]
        result = {**truth_results(seed, levels, [0.2, 0.7]), "rounds_planned": 3 if added else 2}
        make_job(sweep, f"{seed}_s{seed}", [f"seed={seed}"], result=result)
    build_report(sweep, posteriors=False)
    with (sweep / "report" / "calibration.csv").open() as f:
        row = next(csv.DictReader(f))
    assert (row["truths"], row["inside_0.9"], row["rounds_of_0.9"]) == ("9", "9", "9")
    markdown = (sweep / "report" / "report.md").read_text()
    assert "90% region 9/9 = 1.00" in markdown and "| 3 | 2/2 = 1.00" in markdown
    assert "1 unfinished" in markdown


def test_pool_reports_a_study_run_in_parts_as_one_configuration(tmp_path):
    """Seeds 0-5 with device=cuda on one machine, 6-11 on the CPU of another: two configurations by their overrides,
    one with --pool (its 12 truths counted together)."""
    sweep = tmp_path / "sweep"
    for seed in range(12):
        make_job(sweep, f"{seed}_s{seed}", [f"seed={seed}", *(["device=cuda"] if seed < 6 else [])],
                 result=truth_results(seed, [0.3, 0.4], [0.2, 0.7]))
    build_report(sweep, posteriors=False)
    with (sweep / "report" / "calibration.csv").open() as f:
        assert sorted(row["truths"] for row in csv.DictReader(f)) == ["6", "6"]
    assert main([str(sweep), "--no-posteriors", "--pool"]) == 0
    with (sweep / "report" / "calibration.csv").open() as f:
        assert [row["truths"] for row in csv.DictReader(f)] == ["12"]
    assert "12 truths (drawn from the prior)" in (sweep / "report" / "report.md").read_text()
