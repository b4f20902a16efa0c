"""The config against the machine, before anything is built or simulated (machine.py): refusals naming the fix,
and the choice made for the user (signatory's torch backend on a GPU with a CPU-only pysiglib), logged once."""

import importlib.util
import logging

import pysiglib
import pytest
import torch

from bayessim_exp import machine
from bayessim_exp.errors import ConfigError
from bayessim_exp.pipeline import Pipeline
from bayessim_exp.run_config import check_run_config
from bayessim_exp.sim.pool import SimulatorPool

SIGNATORY_ON_GPU = ["summarizer=signatory", "device=cuda"]


@pytest.fixture
def cuda(monkeypatch):
    """A machine whose torch sees one CUDA GPU (nothing is put on it: the config is only checked)."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    monkeypatch.setattr(machine, "_SAID", set())


@pytest.fixture
def no_simulation(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("simulated before the config was checked")

    monkeypatch.setattr(SimulatorPool, "rollout", refuse)


def fitted(compose, overrides):
    cfg = compose(overrides)
    return machine.fit_to_machine(cfg, check_run_config(cfg))


def test_cuda_without_a_gpu_is_refused_naming_the_fix(compose, tmp_path, monkeypatch, no_simulation):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(ConfigError, match=r"^device=cuda: this torch .* sees no CUDA GPU; run with device=cpu$"):
        Pipeline(compose(["device=cuda"]), tmp_path)
    assert not (tmp_path / "config.yaml").exists()


@pytest.mark.parametrize("device, message", [("cuda:1", "torch sees 1 CUDA GPU"), ("meta", "device=cpu, device=cuda")])
def test_a_device_torch_has_no_gpu_for_is_refused(compose, cuda, device, message):
    with pytest.raises(ConfigError, match=message):
        fitted(compose, [f"device={device}"])


def test_signatory_on_a_gpu_with_a_cpu_only_pysiglib_takes_the_torch_backend_said_once(compose, cuda, monkeypatch,
                                                                                        caplog, tmp_path):
    monkeypatch.setattr(pysiglib, "BUILT_WITH_CUDA", False)
    cfg = compose(SIGNATORY_ON_GPU)
    with caplog.at_level(logging.INFO, logger="bayessim_exp.machine"):
        pipeline = Pipeline(cfg, tmp_path / "a")
        Pipeline(cfg, tmp_path / "b")
    assert cfg.summarizer.backend == "pysiglib"  # the caller's config is left as composed
    assert pipeline.cfg.summarizer.backend == "torch"
    assert "backend: torch" in (tmp_path / "a" / "config.yaml").read_text()  # what ran is what is recorded
    said = [r for r in caplog.records if r.name == "bayessim_exp.machine"]
    assert len(said) == 1 and said[0].levelno == logging.WARNING and "summarizer.backend=torch" in said[0].message


@pytest.mark.parametrize("overrides", [SIGNATORY_ON_GPU + ["summarizer.backend=torch"],  # asked for already
                                       ["summarizer=signatory"],  # on the CPU pysiglib runs
                                       ["device=cuda"]])  # no signatures
def test_the_config_is_left_alone_where_the_machine_runs_it(compose, cuda, monkeypatch, overrides):
    monkeypatch.setattr(pysiglib, "BUILT_WITH_CUDA", False)
    cfg = compose(overrides)
    assert machine.fit_to_machine(cfg, check_run_config(cfg)) is cfg


def test_a_pysiglib_built_with_cuda_keeps_its_backend(compose, cuda, monkeypatch):
    monkeypatch.setattr(pysiglib, "BUILT_WITH_CUDA", True)
    assert fitted(compose, SIGNATORY_ON_GPU).summarizer.backend == "pysiglib"


def test_mjx_without_jax_is_refused_naming_the_install(compose, tmp_path, monkeypatch, no_simulation):
    find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "jax" else find_spec(name, *a))
    with pytest.raises(ConfigError, match=r"sim=mjx needs JAX and MJX.*pip install -e '\.\[gpu\]'.*sim=native"):
        Pipeline(compose(["sim=mjx"]), tmp_path)


def test_a_missing_real_data_file_is_refused_before_any_simulation(compose, tmp_path, no_simulation):
    with pytest.raises(ConfigError, match="no such file"):
        Pipeline(compose(["real=file", f"real.path={tmp_path / 'missing.npz'}"]), tmp_path / "run")
