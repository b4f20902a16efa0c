"""Every shipped config builds: each option of each group and each experiment (stored sweeps:
test_sweep_configs.py); and each option's defaults are written once, in its YAML (its dataclass
gives only the types)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml

from bayessim_exp import registry
from bayessim_exp.pipeline import Pipeline

ROOT = Path(__file__).resolve().parents[2]
CONF = ROOT / "conf"
OPTIONS = [(g, p.stem) for g in registry.GROUPS for p in sorted((CONF / g).glob("*.yaml"))]


@pytest.fixture
def real_file(tmp_path):
    path = tmp_path / "pendulum.npz"
    np.savez(path, states=np.zeros((1, 51, 3)), actions=np.zeros((1, 50, 1)))
    return path


@pytest.mark.parametrize("group, name", OPTIONS)
def test_every_option_builds(compose, tmp_path, real_file, group, name):
    extra = [f"real.path={real_file}"] if (group, name) == ("real", "file") else []
    Pipeline(compose([f"{group}={name}", *extra]), tmp_path)


@pytest.mark.parametrize("name", sorted(p.stem for p in (CONF / "experiment").glob("*.yaml")))
def test_every_experiment_builds(compose, tmp_path, name):
    Pipeline(compose([f"experiment={name}"]), tmp_path)


@pytest.mark.parametrize("group, name", OPTIONS)
def test_defaults_are_written_once_in_the_yaml(group, name):
    params = registry.entry(group, name).params
    fields = dataclasses.fields(params)
    with_default = [f.name for f in fields
                    if f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING]
    assert not with_default, f"{params.__name__} repeats defaults of conf/{group}/{name}.yaml: {with_default}"
    text = (CONF / group / f"{name}.yaml").read_text()
    assert text.startswith("#"), "every YAML starts with a comment saying what it is and how to use it"
    keys = set(yaml.safe_load(text)) - {"name", "defaults"}
    assert keys == {f.name for f in fields}
