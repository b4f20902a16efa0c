"""Errors a user can act on: a bad config, bad real data, a failed training run."""


class ConfigError(ValueError):
    """A config value, name or key that is not allowed; the message lists what is."""


class DataError(ValueError):
    """Real trajectories that do not fit the task (shapes, sizes, timestep)."""


class TrainingError(RuntimeError):
    """Training diverged (NaN/inf); the message names the round and step."""


class PosteriorError(RuntimeError):
    """The posterior cannot be formed or sampled (e.g. no mass inside the prior's support)."""


class DataFileError(ValueError):
    """A saved posterior, model or run artifact that is not plain data of an allowed class (or is damaged)."""
