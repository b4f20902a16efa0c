"""A run's name (conf/config.yaml's `run_name`: its run dir under outputs/, a sweep job's dir): the components that
shaped the run and its seed. Methods that use no posterior model and no summarizer (simopt, sysid) are named without
them, and a task=mjcf robot by its MJCF file (every own robot is task `mjcf`)."""

from __future__ import annotations

from pathlib import PurePosixPath

from omegaconf import OmegaConf

WITHOUT_MODEL = ("simopt", "sysid")  # methods that fit no model to summaries


def run_name(task, xml, method, model, summarizer, policy, seed) -> str:
    if task == "mjcf" and xml:
        task = PurePosixPath(str(xml).split("://")[-1]).stem  # pkg://<package>/<path> or a path
    parts = [task, method] + ([] if method in WITHOUT_MODEL else [model, summarizer]) + [policy, f"seed{seed}"]
    return "_".join(str(p) for p in parts)


# conf/config.yaml resolves through this: registered on importing the package, which every composition does first
OmegaConf.register_new_resolver("bayessim_exp.run_name", run_name, replace=True)
