"""benchmarks/results.py assembles docs/results.md: the committed page is a fixed point of the assembly, a
regenerated section replaces only its own block, and every section renders from canned outputs of its jobs
(the end-to-end --quick run is tests/integration/test_results_quick.py)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
import yaml

import results  # benchmarks/results.py (pyproject.toml's pytest pythonpath)
from results_sections import Context, Job, MethodsSection, RlSection, ScriptSection, SectionError

ROOT = Path(__file__).resolve().parents[2]


def test_the_committed_page_is_what_the_assembler_writes_from_it():
    page = (ROOT / "docs" / "results.md").read_text()
    assert results.assemble(page, {}) == page
    assert [name for name, _ in results.BLOCK.findall(page)] == [s.name for s in results.SECTIONS]


def test_a_regenerated_section_replaces_its_block_only_and_a_missing_one_is_named():
    page = results.assemble("", {"methods": "## Methods\n\nnew text"})
    assert "new text" in page and "--sections rl_posterior_vs_prior" in page
    again = results.assemble(page, {"rl_posterior_vs_prior": "## PPO\n\nppo text"})
    assert "new text" in again and "ppo text" in again and "Not generated yet" not in again.split("end methods")[0]


def _fake_run(path: Path, task: str, method: str, seed: int, names: list[str], mean: float, std: float,
              hpd_level: float | None = None, truth: float = 1.0) -> None:
    path.mkdir(parents=True)
    cfg = {"rounds": 2, "real": {"per_round": 1}, "collect": {"horizon": 20, "trajectories": 300},
           "policy": {"name": "random"}, "model": {"name": "mdnn"}, "summarizer": {"name": "start"},
           "method": {"name": method, "updates": 5, "min_std": 0.005, "rollout": "recorded", "proposal": "truncated",
                      "parameter_space": "auto", "starts": 3, "max_iters": 50, "min_noise_std": 0.01}}
    (path / "config.yaml").write_text(yaml.safe_dump(cfg))
    last = {"posterior_mean": {n: mean for n in names}, "posterior_std": {n: std for n in names},
            "log_prob_true_posterior": 1.5, "log_prob_gain": 1.0, "real_trajectories": 2, "sim_trajectories": 300}
    if hpd_level is not None:  # a known-truth run: where its truth lies in its final posterior
        last = {**last, "truth": {"hpd_level": hpd_level, "marginal_rank": {n: 0.5 for n in names}}}
    (path / "results.json").write_text(json.dumps({
        "task": task, "method": method, "seed": seed, "param_names": names, "true_params": {n: truth for n in names},
        "prior": {"low": {n: 0.5 for n in names}, "high": {n: 2.0 for n in names}}, "rounds": [last, last]}))


# each method's truths at planted HPD levels: BayesSim's spread evenly (calibrated), SimOpt's all outside its
# regions (overconfident), sysid's all at its mode (too wide)
PLANTED = {"bayessim": [0.05 + 0.1 * i for i in range(10)], "simopt": [0.99] * 10, "sysid": [0.01] * 10}


def test_the_methods_section_quotes_what_its_runs_measured(tmp_path):
    ctx = Context(work=tmp_path, figures=tmp_path / "figures", quick=False, jobs=14)
    section = MethodsSection()
    offset = {"bayessim": 0.1, "simopt": 0.001, "sysid": 0.0001}
    for point in section.grid(quick=False):
        task, method = point["task"], point["method"]
        names = ["mass", "length"] if task == "Pendulum" else ["cart_mass", "pole_mass", "motor_gain"]
        mean = 1.0 + offset[method] + (0.01 * point["seed"] if method == "bayessim" else 0)
        _fake_run(tmp_path / "sweep" / f"{task}_{method}_{point['seed']}", task, method, point["seed"], names, mean,
                  0.0075 if method == "simopt" else 0.05)
    for task, method in section.pairs(quick=False):
        names = ["mass", "length"] if task == "Pendulum" else ["cart_mass", "pole_mass", "motor_gain"]
        for seed, level in enumerate(PLANTED[method]):
            _fake_run(tmp_path / "calibration" / f"{task}_{method}" / f"seed{seed}", task, method, seed, names,
                      1.0 + offset[method], 0.05, hpd_level=level, truth=1.0 + 0.01 * seed)  # a truth per seed
    _fake_run(tmp_path / "closed_loop", "Pendulum", "simopt", 0, ["mass", "length"], 1.6, 0.2)
    text = section.render(ctx, "STAMP")
    assert text.startswith("## BayesSim, SimOpt and MuJoCo's sysid") and "STAMP" in text and "$" not in text
    assert "| Pendulum | simopt | 3 |" in text and "| Cartpole | bayessim | 3 |" in text and "| Cartpole | sysid | 3 |" in text
    assert ("mean error / range 0.073 (bayessim), 0.00067 (simopt), 6.7e-05 (sysid), sysid closest") in text
    assert "at its floor (`method.min_std` = 0.005 of each range) in 3 of 3 seeds" in text
    assert "mean error 0.4 of the range against 0.00067 with `recorded`" in text
    # the known-truth study: shares with their exact intervals, marked where the interval leaves out the level
    assert "| Pendulum | bayessim | 10 | 5/10 = 0.50 [0.19, 0.81] | 9/10 = 0.90 [0.55, 1.00] |" in text
    assert "| Cartpole | simopt | 10 | 0/10 = 0.00 [0.00, 0.31] (too narrow) | 0/10 = 0.00 [0.00, 0.31] (too narrow) |" in text
    assert "| Cartpole | sysid | 10 | 10/10 = 1.00 [0.69, 1.00] (too wide) | 10/10 = 1.00 [0.69, 1.00] |" in text
    assert "truths inside the final 90 % region: bayessim 9 of 10, simopt 0 of 10 (too narrow), sysid 10 of 10." in text
    assert "S = 0..9, each (T, M) above" in text


def test_the_methods_section_refuses_a_study_with_a_run_missing(tmp_path):
    ctx = Context(work=tmp_path, figures=tmp_path / "figures", quick=True, jobs=2)
    section = MethodsSection()
    for point in section.grid(quick=True):
        _fake_run(tmp_path / "sweep" / f"{point['method']}", "Pendulum", point["method"], 0, ["mass"], 1.0, 0.05)
    _fake_run(tmp_path / "closed_loop", "Pendulum", "simopt", 0, ["mass"], 1.6, 0.2)
    for task, method in section.pairs(quick=True):
        for seed in (0, 1):  # a truth per seed
            _fake_run(tmp_path / "calibration" / f"{task}_{method}" / f"seed{seed}", task, method, seed, ["mass"], 1.0,
                      0.05, 0.3, truth=1.0 + 0.01 * seed)
    (tmp_path / "calibration" / "Pendulum_sysid" / "seed2").mkdir()
    (tmp_path / "calibration" / "Pendulum_sysid" / "seed2" / "error.txt").write_text("killed")
    with pytest.raises(SectionError, match="Pendulum sysid: 2 of 3 known-truth runs"):
        section.render(ctx, "STAMP")


def test_the_ppo_section_writes_its_figure_and_table(tmp_path):
    ctx = Context(work=tmp_path, figures=tmp_path / "figures", quick=False, jobs=14)
    settings = {"prior": {"low": {"mass": 0.5, "length": 0.25}, "high": {"mass": 2.0, "length": 1.0}},
                "trajectories": 10000, "summarizer": "start", "model": "mdnn", "proposal": "truncated",
                "ppo_steps": 150000, "ppo_envs": 64, "episodes": 32, "episode_length": 200}
    for seed in RlSection.seeds:
        def policy(score, seed=seed):
            return {"surrogate_real_return": {"mean": score - seed, "min": score - 500, "max": score + 300},
                    "rl_training": {"seconds": 40.0 + seed, "last_episode_return": -600.0}}
        run = {"seed": seed, "bayessim_seconds": 90.0, "posterior_mean": [1.7, 0.9], "posterior_std": [0.1, 0.005],
               "posterior": policy(-340.0), "prior": policy(-1000.0), "nominal": policy(-700.0)}
        (tmp_path / f"seed{seed}.json").write_text(json.dumps(
            {"task": "Pendulum", "real": ["mass=1.8", "length=0.9"], "rounds": 2, "settings": settings, "runs": [run]}))
    text = RlSection().render(ctx, "STAMP")
    assert "$" not in text and "gravity torque of up to 7.9 N m" in text
    assert "| round-2 posterior | -340.0 | -341.0 | -342.0 | **-341.0** | 1.0 |" in text
    assert "scored best on 3 of 3 seeds, by 360 over the next best there" in text
    assert json.loads((ctx.figures / "rl_posterior_vs_prior.json").read_text())["rounds"] == 2
    assert (ctx.figures / "rl_posterior_vs_prior.png").stat().st_size > 0


def test_a_script_section_is_its_scripts_stdout_under_the_stamp_and_a_failing_one_is_reported(tmp_path, capsys):
    script = tmp_path / "section.py"
    script.write_text("import sys\nprint('## Foreign dynamics\\n\\nA table.')\nprint('progress', file=sys.stderr)\n")
    broken = tmp_path / "broken.py"
    broken.write_text("raise SystemExit('no data')\n")
    ctx = Context(work=tmp_path / "work", figures=tmp_path, quick=True, jobs=2)
    good, bad = ScriptSection("foreign", str(script), quick_args=("--tiny",)), ScriptSection("bad", str(broken))
    seconds = results.run_jobs(good.jobs(ctx) + bad.jobs(ctx), 2, tmp_path / "logs", [], lambda job, s: None)
    assert seconds["bad"] is None and "no data" in capsys.readouterr().out
    assert good.render(ctx, "STAMP").splitlines() == [
        "## Foreign dynamics", "", f"`python {script} --tiny`: STAMP", "", "A table."]


def test_quick_mode_refuses_to_write_into_docs(monkeypatch):
    monkeypatch.setattr(sys, "argv", ["results.py", "--quick", "--out", str(ROOT / "docs" / "results.md")])
    with pytest.raises(SystemExit, match="outside docs"):
        results.main()


def _env_job(name: str, out: Path, gpu: bool) -> Job:
    """A job that writes the GPU it sees, holding it a moment so that the jobs overlap."""
    code = "import os, time; time.sleep(0.5); print(os.environ.get('CUDA_VISIBLE_DEVICES', 'all'))"
    return Job(name, [sys.executable, "-c", code], 1.0, stdout=out / f"{name}.txt", gpu=gpu)


def test_gpu_jobs_each_see_one_gpu_of_the_slots_and_cpu_jobs_are_left_alone(tmp_path, monkeypatch):
    monkeypatch.delenv("CUDA_VISIBLE_DEVICES", raising=False)
    jobs = [_env_job(f"gpu{i}", tmp_path, True) for i in range(6)] + [_env_job("cpu", tmp_path, False)]
    finished = []
    results.run_jobs(jobs, 7, tmp_path / "logs", ["0", "1", "0", "1"], lambda job, s: finished.append(job.name))
    seen = {j.name: (tmp_path / f"{j.name}.txt").read_text().strip() for j in jobs}
    assert seen.pop("cpu") == "all" and sorted(set(seen.values())) == ["0", "1"]
    assert sorted(finished) == sorted(j.name for j in jobs)


def test_a_killed_call_renders_what_finished_only_and_a_resumed_one_names_both_calls(tmp_path, monkeypatch):
    script = tmp_path / "section.py"
    script.write_text("print('## Section\\n\\nA table.')\n")
    monkeypatch.setattr(results, "SECTIONS", [ScriptSection("one", str(script), quick_args=())])
    argv = ["results.py", "--quick", "--jobs", "1", "--out", str(tmp_path / "out" / "results.md"),
            "--work", str(tmp_path / "work")]
    monkeypatch.setattr(sys, "argv", argv)
    results.main()
    first = (tmp_path / "out" / "results.md").read_text()
    monkeypatch.setattr(sys, "argv", argv + ["--render-only"])
    results.main()
    stamped, _ = first.split(" s in all.")  # the first call's stamp, read from the work dir, then the rendering's
    assert (tmp_path / "out" / "results.md").read_text().startswith(stamped + " s in all; rendered by --render-only at ")
    record = tmp_path / "work" / "one" / "generated.json"
    killed = {**json.loads(record.read_text()), "seconds": {}}  # as if the call had been killed before its job ended
    record.write_text(json.dumps(killed))
    with pytest.raises(SystemExit, match="failed: one"):
        results.main()
    monkeypatch.setattr(sys, "argv", argv + ["--resume"])
    results.main()
    resumed = json.loads(record.read_text())
    assert resumed["line"].startswith(killed["line"] + "; resumed commit ") and list(resumed["seconds"]) == ["one"]
