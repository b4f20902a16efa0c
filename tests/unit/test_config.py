"""Every shipped config builds: each option of each group and each experiment (stored sweeps:
test_sweep_configs.py); and each option's defaults are written once, in its YAML (its dataclass
gives only the types)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml
from omegaconf import OmegaConf

from bayessim_exp import registry
from bayessim_exp.pipeline import Pipeline
from bayessim_exp.testing.robot_logs import NAMES, pendulum_frames, write_csv, write_lerobot

ROOT = Path(__file__).resolve().parents[2]
CONF = ROOT / "conf"
OPTIONS = [(g, p.stem) for g in registry.GROUPS for p in sorted((CONF / g).glob("*.yaml"))]


@pytest.fixture
def real_paths(tmp_path):
    """A Pendulum log of 50 steps at rest for each option of `real` that reads one."""
    states, actions = np.tile([1.0, 0.0, 0.0], (1, 51, 1)), np.zeros((1, 50, 1))
    np.savez(tmp_path / "pendulum.npz", states=states, actions=actions)
    table = {"time": np.arange(51) * 0.05, "cos_theta": states[0, :, 0], "sin_theta": states[0, :, 1],
             "theta_dot": states[0, :, 2], "torque": np.zeros(51)}
    return {"file": tmp_path / "pendulum.npz", "csv": write_csv(tmp_path / "pendulum.csv", table),
            "lerobot": write_lerobot(tmp_path / "lerobot", pendulum_frames(states, actions), NAMES)}


EXPERIMENTS = [("experiment", p.stem) for p in sorted((CONF / "experiment").glob("*.yaml"))]


@pytest.mark.parametrize("budget", [[], ["debug=smoke"]], ids=["default", "smoke"])
@pytest.mark.parametrize("group, name", OPTIONS + EXPERIMENTS)
def test_every_option_builds(compose, tmp_path, real_paths, group, name, budget):
    """What the pipeline checks and builds before simulating (Pipeline.__init__: the run's keys, every component
    with its parameters), for each option varied alone from the defaults, and under debug=smoke: a debug budget
    may not name a key that an option lacks (model=linear has no epochs: conf/model_debug)."""
    extra = [f"real.path={real_paths[name]}"] if group == "real" and name in real_paths else []
    Pipeline(compose([f"{group}={name}", *extra, *budget]), tmp_path)


@pytest.mark.parametrize("name", [name for group, name in OPTIONS if group == "model"])
def test_smoke_shrinks_the_epochs_of_every_model_trained_in_epochs(compose, name):
    full, smoke = compose([f"model={name}"]).model, compose([f"model={name}", "debug=smoke"]).model
    if "max_epochs" in full:  # conf/model_debug/<name>_smoke.yaml
        assert smoke.max_epochs < full.max_epochs and smoke.patience < full.patience


def test_smoke_shrinks_the_importance_sampled_posteriors_and_a_tiny_pool_is_refused(compose, tmp_path):
    from bayessim_exp.errors import ConfigError

    assert compose(["debug=smoke"]).method.importance_draws < compose([]).method.importance_draws  # conf/method_debug
    with pytest.raises(ConfigError, match="importance_draws must be >= 1000"):
        Pipeline(compose(["method.importance_draws=10"]), tmp_path)


@pytest.mark.parametrize("group, name", OPTIONS)
def test_defaults_are_written_once_in_the_yaml(compose, group, name):
    text = (CONF / group / f"{name}.yaml").read_text()
    assert text.startswith("#"), "every YAML starts with a comment saying what it is and how to use it"
    registered = compose([f"{group}={name}"])[group].name
    params = registry.entry(group, registered).params
    fields = dataclasses.fields(params)
    with_default = [f.name for f in fields
                    if f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING]
    assert not with_default, f"{params.__name__} repeats defaults of conf/{group}/{registered}.yaml: {with_default}"
    keys = set(yaml.safe_load(text)) - {"name", "defaults"}
    if registered == name:  # its YAML's keys with those of the blocks it shares (conf/model/training)
        assert set(registry.option_defaults(group, name)) - {"name"} == {f.name for f in fields}
    else:  # a variant of a registered option (its defaults list names it) writes only what it changes
        assert keys and keys <= {f.name for f in fields}


@pytest.mark.parametrize("name", [name for group, name in OPTIONS if group == "model"])
def test_no_model_writes_a_key_of_the_training_block_it_names(name):
    """A model names conf/model/training after its _self_ (the block's file says why), so a key written in both would
    take the block's value: a model needing another names a variant of the block (uncalibrated.yaml)."""
    doc = yaml.safe_load((CONF / "model" / f"{name}.yaml").read_text())
    if any(isinstance(d, dict) and "training@_here_" in d for d in doc.get("defaults", [])):
        block = yaml.safe_load((CONF / "model" / "training" / "default.yaml").read_text())
        assert not set(doc) & set(block)


# each task's inference defaults (its YAML's defaults list; measured in docs/tasks.md)
TASK_DEFAULTS = {  # summarizer, model, covariance, project_inputs, components, ensemble, method.calibrate_on
    "Pendulum": ("start", "mdnn", "full", False, 5, 1, "latest"),
    "Cartpole": ("corrdiff", "mdnn", "full", True, 1, 3, "all"),  # conf/method_task/bayessim_Cartpole.yaml
    "Ant": ("corrdiff", "mdnn", "diagonal", True, 5, 1, "latest"),
    "Humanoid": ("corrdiff", "mdnn", "diagonal", True, 1, 1, "latest"),
    "ShadowHand": ("corrdiff", "mdnn", "full", True, 1, 3, "latest"),
    "ShadowHand_more": ("corrdiff", "mdnn", "diagonal", True, 5, 3, "latest"),
}


@pytest.mark.parametrize("task", sorted(TASK_DEFAULTS))
def test_a_task_chooses_its_inference_defaults(compose, task):
    cfg = compose([f"task={task}"])
    m = cfg.model
    assert (cfg.summarizer.name, m.name, m.covariance, m.project_inputs, m.components, m.ensemble,
            cfg.method.calibrate_on) == TASK_DEFAULTS[task]
    assert cfg.method.parameter_space == "auto"


def test_the_command_line_beats_a_tasks_method_settings_and_another_method_gets_none(compose):
    for overrides in (["task=Cartpole", "method.calibrate_on=latest"], ["method.calibrate_on=latest", "task=Cartpole"]):
        assert compose(overrides).method.calibrate_on == "latest"
    assert compose(["task=Cartpole", "method=bayessim"]).method.calibrate_on == "all"
    assert "calibrate_on" not in compose(["task=Cartpole", "method=simopt"]).method


@pytest.mark.parametrize("override, key, value", [
    ("summarizer=start", "summarizer.name", "start"),
    ("model=flow", "model.name", "flow"),
    ("model=mdnn", "model.covariance", "full"),
    ("model.components=2", "model.components", 2),
    ("method=simopt", "method.name", "simopt"),
    ("method.parameter_space=box", "method.parameter_space", "box"),
])
def test_the_command_line_beats_a_task_default(compose, override, key, value):
    for overrides in (["task=Ant", override], [override, "task=Ant"]):  # in either order
        assert OmegaConf.select(compose(overrides), key) == value
    assert compose(["task=Ant", override]).summarizer.name == ("start" if override == "summarizer=start" else "corrdiff")


def test_an_experiment_beats_a_task_default(compose):
    cfg = compose(["task=Ant", "experiment=bayessimig_pendulum"])
    assert (cfg.task.name, cfg.summarizer.name, cfg.model.covariance) == ("Ant", "start", "full")


@pytest.mark.parametrize("override, message", [
    ("rounds=0", "rounds=0: need rounds >= 1"),
    ("collect.trajectories=5", "collect.trajectories=5: need collect.trajectories >= 20"),
    ("diagnostics.replay_sims=1", r"diagnostics.replay_sims=1: need diagnostics.replay_sims 0 \(off\) or >= 2"),
    ("diagnostics.levels=[0.5,1.5]", r"diagnostics.levels=\[0.5, 1.5\]: need diagnostics.levels each in \(0, 1\)"),
])
def test_an_out_of_range_run_key_is_named_with_its_value(compose, override, message):
    from bayessim_exp.errors import ConfigError
    from bayessim_exp.run_config import check_run_config

    with pytest.raises(ConfigError, match=f"^{message}$"):
        check_run_config(compose([override]))


@pytest.mark.parametrize("overrides, name", [
    ([], "Pendulum_bayessim_mdnn_start_random_seed0"),
    (["method=sysid", "seed=3"], "Pendulum_sysid_random_seed3"),  # no model, no summarizer
    (["method=simopt", "task=Cartpole"], "Cartpole_simopt_random_seed0"),
    (["task=mjcf"], "two_link_arm_bayessim_mdnn_start_random_seed0"),  # the shipped arm, pkg://...
    (["task=mjcf", "task.xml=myrobot/arm.xml"], "arm_bayessim_mdnn_start_random_seed0"),
])
def test_a_run_is_named_by_what_shaped_it(compose, overrides, name):
    assert compose(overrides).run_name == name
