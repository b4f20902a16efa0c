"""sim=auto's choice per task: MJX on a GPU, native MuJoCo where the task's tuning lists the MJX implementation
found there in `native_faster_on` (measured faster), and benchmarks/auto_choice.py's table from the same
decision. No MJX is built: MjxSimulator is a stand-in recording its arguments."""

from __future__ import annotations

import json
import logging

import pytest

import auto_choice  # benchmarks/auto_choice.py (pyproject.toml's pytest pythonpath)
from bayessim_exp import registry
from bayessim_exp.errors import ConfigError
from bayessim_exp.sim import auto as sim_auto
from bayessim_exp.sim import mjx as sim_mjx
from bayessim_exp.sim import mjx_impl
from bayessim_exp.sim.mjx_tuning import tuned_model
from bayessim_exp.sim.native import NativeSimulator

NATIVE_ON_JAX = ["task=Pendulum", "++sim.tuning.native_faster_on=[jax]", "sim.native_below=4"]


@pytest.fixture
def gpu(monkeypatch):
    """gpu(impl): a machine whose GPU JAX sees, sim.impl resolving to `impl`; returns the stand-in's calls."""
    built = []

    def on(impl: str) -> list:
        monkeypatch.setattr(sim_auto, "gpu_visible", lambda: True)
        for module in (sim_auto, sim_mjx, mjx_impl):
            monkeypatch.setattr(module, "resolve_impl", lambda asked, tuning=None: impl)
        monkeypatch.setattr(sim_mjx, "MjxSimulator", lambda task, n, cfg: built.append((task.name, n, cfg)) or "mjx")
        monkeypatch.setattr(sim_auto, "_LOGGED", set())
        monkeypatch.setattr(sim_mjx, "_LOGGED", set())
        return built

    return on


def make_for(compose, overrides):
    cfg = compose(overrides)
    return registry.build("task", cfg.task), registry.build("sim", cfg.sim)


@pytest.mark.parametrize("impl, listed", [("jax", True), ("warp", False)])
def test_auto_simulates_natively_where_the_implementation_found_is_listed(compose, gpu, impl, listed):
    built = gpu(impl)
    task, make = make_for(compose, ["sim=auto", *NATIVE_ON_JAX])
    sim = make(task, 8)
    if listed:
        assert isinstance(sim, NativeSimulator) and sim.model is task.model and not built  # the stock model
    else:
        assert sim == "mjx" and built[0][:2] == ("Pendulum", 8) and built[0][2].tuning["native_faster_on"] == ["jax"]


def test_auto_without_a_gpu_and_on_an_unlisted_task_keeps_its_choice(compose, gpu, monkeypatch):
    built = gpu("jax")
    task, make = make_for(compose, ["task=Pendulum", "sim=auto", "sim.native_below=4"])
    assert make(task, 8) == "mjx" and len(built) == 1
    monkeypatch.setattr(sim_auto, "gpu_visible", lambda: False)
    task, make = make_for(compose, ["task=Pendulum", "sim=auto", "sim.native_below=4"])
    assert isinstance(make(task, 8), NativeSimulator) and len(built) == 1


def test_auto_says_once_per_task_that_native_measured_faster(compose, gpu, caplog):
    gpu("jax")
    task, make = make_for(compose, ["sim=auto", *NATIVE_ON_JAX])
    with caplog.at_level(logging.INFO, logger=sim_auto.__name__):
        make(task, 8), make(task, 16)
    said = [r.getMessage() for r in caplog.records if "native measured faster" in r.getMessage()]
    assert len(said) == 1
    assert "Pendulum" in said[0] and "MJX's jax implementation" in said[0] and "docs/benchmarks.md" in said[0]


def test_an_explicit_sim_mjx_simulates_on_mjx_and_says_native_measured_faster(compose, gpu, caplog):
    built = gpu("jax")
    task, make = make_for(compose, ["sim=mjx", *NATIVE_ON_JAX])
    with caplog.at_level(logging.INFO, logger=sim_mjx.__name__):
        make(task, 8), make(task, 16)
    assert [b[:2] for b in built] == [("Pendulum", 8), ("Pendulum", 16)]
    said = [r for r in caplog.records if "native MuJoCo" in r.getMessage() and "measured faster" in r.getMessage()]
    assert len(said) == 1 and said[0].levelno == logging.WARNING and "jax" in said[0].getMessage()


@pytest.mark.parametrize("value", ["[cuda]", "jax", "3", "[[jax]]"])
def test_native_faster_on_names_mjx_implementations_only(compose, value):
    with pytest.raises(ConfigError, match="native_faster_on.*jax, warp"):
        registry.build("sim", compose(["task=Pendulum", "sim=auto", f"++sim.tuning.native_faster_on={value}"]).sim)


def test_humanoid_carries_mjx_contact_caps_in_its_tuning(compose):
    tuning = compose(["task=Humanoid", "sim=auto"]).sim.tuning
    assert (tuning.min_condim, tuning.max_geom_pairs, tuning.max_contact_points) == (3, 8, 8)
    assert compose(["experiment=gpu_humanoid"]).sim.tuning == tuning  # the experiment no longer repeats them
    model = tuned_model(registry.build("task", compose(["task=Humanoid"]).task), tuning)
    assert {model.numeric(n).data[0] for n in ("max_geom_pairs", "max_contact_points")} == {8.0}


ROWS = [{"task": "Humanoid", "backend": "native", "impl": "-", "envs": 4096, "env_steps_per_s": 80_000.0},
        {"task": "Humanoid", "backend": "mjx", "impl": "jax", "envs": 4096, "env_steps_per_s": 200_000.0},
        {"task": "Ant", "backend": "native", "impl": "-", "envs": 4096, "env_steps_per_s": 50_000.0},
        {"task": "Ant", "backend": "mjx", "impl": "jax", "envs": 4096, "env_steps_per_s": 30_000.0},
        {"task": "ShadowHand", "error": "RuntimeError: out of memory"}]


def test_the_auto_table_shows_the_factorys_choice_and_whether_the_tuning_is_right():
    listed = {"Humanoid": {}, "Ant": {"native_faster_on": ["jax"]}}
    lines = {line[0]: line for line in auto_choice.table(ROWS, listed.get)}
    assert lines["Humanoid"][5:] == ("MJX (jax)", "yes", "right")
    assert lines["Ant"][3:] == ("50,000", "30,000", "native", "yes", "right")
    assert "FAILED" in lines["ShadowHand"][-1]
    wrong = {line[0]: line for line in auto_choice.table(ROWS, {"Humanoid": {"native_faster_on": ["jax"]},
                                                                  "Ant": {}}.get)}
    assert wrong["Humanoid"][5:] == ("native", "yes", "drop jax from native_faster_on")
    assert wrong["Ant"][5:] == ("MJX (jax)", "no", "add jax to native_faster_on")


def test_the_auto_table_script_reads_sim_throughputs_json_on_a_cpu(tmp_path, capsys):
    path = tmp_path / "auto_table.json"
    path.write_text(json.dumps({"device": "cuda:0", "impl": "jax", "overrides": [], "rows": ROWS}))
    auto_choice.main([str(path)])
    out = capsys.readouterr().out.splitlines()
    assert out[1].startswith("| task | implementation |") and len(out) == 6
    # Ant's tuning lists jax (conf/mjx_tuning): these rows agree
    assert "| Ant | jax | 4,096 | 50,000 | 30,000 | native | yes | right |" in out
