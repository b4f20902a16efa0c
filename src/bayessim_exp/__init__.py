"""BayesSim on MuJoCo: posteriors over simulator parameters from real trajectories."""

__version__ = "0.1.0"

from . import run_name as _run_name  # noqa: E402,F401 - registers the resolver of conf/config.yaml's run_name
