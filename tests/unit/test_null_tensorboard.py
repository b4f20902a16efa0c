"""logging/tensorboard.py's NO_TENSORBOARD, which stages run outside a run (api.Run.posterior, StandaloneRounds, the
benchmarks that read saved rounds) log to: stages call ctx.tb's methods unconditionally."""

import inspect

import pytest

from bayessim_exp.logging.tensorboard import NO_TENSORBOARD, TensorBoardLogger


def test_the_null_writer_answers_every_method_of_the_logger_and_nothing_else():
    """Each of TensorBoardLogger's public methods is taken and does nothing (a method added to the logger alone would
    otherwise break every stage run outside a run); a name the logger lacks is refused, as the logger would."""
    methods = [name for name, member in inspect.getmembers(TensorBoardLogger, inspect.isfunction)
               if not name.startswith("_")]
    assert {"scalar", "scalars", "posterior", "losses", "image", "close"} <= set(methods)
    for name in methods:
        assert getattr(NO_TENSORBOARD, name)(1, "tag", x=2) is None
    with pytest.raises(AttributeError, match="no_such_method"):
        NO_TENSORBOARD.no_such_method  # noqa: B018
