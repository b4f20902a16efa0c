"""Every stored sweep and launcher preset composes, names only options that exist, and says how to run it."""

import subprocess
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import OmegaConf

from bayessim_exp import registry
from bayessim_exp.run_config import check_run_config

REPO = Path(__file__).resolve().parents[2]
SWEEPS = sorted((REPO / "sweeps").glob("*.yaml"))
LAUNCHERS = sorted((REPO / "conf" / "hydra" / "launcher").glob("*.yaml"))


@pytest.mark.parametrize("path", SWEEPS + LAUNCHERS, ids=lambda p: p.stem)
def test_starts_with_a_comment_naming_its_command(path):
    head = path.read_text().splitlines()[:3]
    assert head[0].startswith("# ") and any("python -m bayessim_exp" in line or "make sweep" in line for line in head)


def compose_sweep(name: str, overrides=(), hydra=False):
    """As `python -m bayessim_exp --config-dir sweeps --config-name <name>` composes it."""
    from bayessim_exp.api import CONF_DIR

    with initialize_config_dir(config_dir=str(REPO / "sweeps"), version_base="1.3"):
        return compose(config_name=name, overrides=[f"hydra.searchpath=[file://{CONF_DIR.resolve()}]", *overrides],
                       return_hydra_config=hydra)


def sweep_values(name: str):
    """The sweep's config and, per swept key, its values as they are typed on the command line and as parsed."""
    cfg = compose_sweep(name, hydra=True)
    parsed = OverridesParser.create().parse_overrides([f"{k}={v}" for k, v in cfg.hydra.sweeper.params.items()])
    return cfg, {o.key_or_group: list(zip(o.sweep_string_iterator(), o.sweep_iterator())) if o.is_sweep_override()
                 else [(str(o.value()), o.value())] for o in parsed}


def check_job(job) -> None:
    check_run_config(job)
    for group in registry.GROUPS:
        registry.parse_params(group, job[group])


@pytest.mark.parametrize("path", SWEEPS, ids=lambda p: p.stem)
def test_every_swept_value_composes_to_a_valid_run(path):
    """Each value of a config group is composed and checked whole. A plain key's first value too; its other values
    are set on that composed job, as Hydra sets a plain key after composing, and the job checked whole again (a
    composition per seed of seed=range(100) took most of a minute)."""
    from bayessim_exp.api import CONF_DIR

    cfg, values = sweep_values(path.stem)
    assert str(cfg.hydra.sweep.dir).startswith(f"multirun/{path.stem}/")  # the sweep dir carries its name
    assert len(values.get("seed", [])) >= 3  # a spread over seeds, not one run
    for key, options in values.items():
        if (CONF_DIR / key).is_dir():  # a config group: each option composes its own config
            for typed, _ in options:
                check_job(compose_sweep(path.stem, [f"{key}={typed}"]))
            continue
        job = compose_sweep(path.stem, [f"{key}={options[0][0]}"])
        check_job(job)
        for _, value in options[1:]:
            OmegaConf.update(job, key, value)
            check_job(job)


def launcher(overrides):
    from bayessim_exp.api import CONF_DIR

    with initialize_config_dir(config_dir=str(CONF_DIR.resolve()), version_base="1.3"):
        return compose(config_name="config", overrides=overrides, return_hydra_config=True).hydra.launcher


def slurm_executor(preset, folder, monkeypatch):
    """The submitit executor hydra-submitit-launcher builds from a preset (submitit_launcher.py: keys outside
    BaseQueueConf get the slurm_ prefix). Building it needs no cluster except that submitit's constructor looks
    for `srun` on PATH (submitit/slurm/slurm.py, SlurmExecutor.affinity): that lookup alone is faked; every key is
    still checked, and the sbatch script rendered, by submitit itself."""
    import submitit
    from hydra_plugins.hydra_submitit_launcher.config import BaseQueueConf
    from submitit.slurm.slurm import SlurmExecutor

    monkeypatch.setattr(SlurmExecutor, "affinity", classmethod(lambda cls: 2))
    params = OmegaConf.to_container(preset, resolve=False)
    params.pop("_target_"), params.pop("submitit_folder")
    params["name"] = "job"  # ${hydra.job.name} resolves only inside a run
    executor = submitit.AutoExecutor(folder=folder, cluster="slurm",
                                     slurm_max_num_timeout=params.pop("max_num_timeout"))
    base = set(OmegaConf.structured(BaseQueueConf).keys())
    # raises on unknown keys
    executor.update_parameters(**{k if k in base else f"slurm_{k}": v for k, v in params.items()})
    return executor


def test_slurm_presets_take_overrides_and_submitit_accepts_every_key(tmp_path, monkeypatch):
    gpu = launcher(["hydra/launcher=slurm_gpu", "hydra.launcher.partition=a100", "hydra.launcher.timeout_min=30",
                    "hydra.launcher.srun_args=['--cpu-bind=none']", "hydra.launcher.setup=['module load cuda']"])
    assert (gpu.partition, gpu.timeout_min, gpu.gpus_per_node, gpu.cpus_per_task, gpu.mem_gb) == ("a100", 30, 1, 8, 32)
    assert list(gpu.srun_args) == ["--cpu-bind=none"]
    assert gpu.max_num_timeout > 0  # timed-out jobs are requeued: stages resume from the run dir
    cpu = launcher(["hydra/launcher=slurm_cpu"])
    assert cpu.gpus_per_node is None
    slurm_executor(cpu, tmp_path / "cpu", monkeypatch)
    executor = slurm_executor(gpu, tmp_path / "gpu", monkeypatch)
    # the sbatch script as it would be submitted (what sbatch itself does with it needs a cluster: test_slurm.py)
    script = executor._executor._make_submission_file_text("python -u -m submitit.core._submit folder", "uid")
    for line in ("#SBATCH --partition=a100", "#SBATCH --time=30", "#SBATCH --gpus-per-node=1",
                 "#SBATCH --cpus-per-task=8", "#SBATCH --mem=32GB", "#SBATCH --signal=USR2@120", "module load cuda"):
        assert line in script.splitlines(), line
    assert "srun --unbuffered" in script and "--cpu-bind=none python -u -m submitit.core._submit" in script
    (tmp_path / "job.sh").write_text(script)
    assert subprocess.run(["bash", "-n", str(tmp_path / "job.sh")]).returncode == 0  # valid shell
    with pytest.raises(NameError, match="partiton"):  # submitit refuses a key it does not know
        executor.update_parameters(slurm_partiton="x")
    with pytest.raises(Exception, match="partiton"):  # and Hydra refuses it first
        launcher(["hydra/launcher=slurm_cpu", "hydra.launcher.partiton=x"])


def test_local_preset_is_the_joblib_launcher():
    local = launcher(["hydra/launcher=local", "hydra.launcher.n_jobs=3"])
    assert local._target_.endswith("JoblibLauncher") and local.n_jobs == 3
