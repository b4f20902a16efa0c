"""Shared fixtures: Hydra composition and a built Pendulum task."""

import os

import pytest

os.environ.setdefault("OMP_NUM_THREADS", "1")


@pytest.fixture
def compose():
    """compose(overrides) -> the config the CLI would build."""
    from bayessim_exp.api import compose as _compose

    return _compose


@pytest.fixture
def pendulum(compose):
    from bayessim_exp import registry

    return registry.build("task", compose([]).task)
