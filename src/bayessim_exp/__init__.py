"""BayesSim on MuJoCo: posteriors over simulator parameters from real trajectories."""

__version__ = "0.1.0"
