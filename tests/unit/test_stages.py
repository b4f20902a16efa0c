"""stages.py's note once per round: a message logged from inside a loop reaches the console once per round of a run."""

import logging

from bayessim_exp.artifacts import RunDir
from bayessim_exp.logging.tensorboard import NO_TENSORBOARD
from bayessim_exp.stages import RoundContext, Stage, info_once_per_round, run_stage

log = logging.getLogger("bayessim_exp.test_note")


def noisy(ctx):
    for _ in range(3):
        info_once_per_round(log, "a note from a loop")
    return {}


def test_a_note_is_logged_once_per_round_of_each_run_and_every_time_outside_a_stage(tmp_path, caplog):
    caplog.set_level(logging.INFO, logger=log.name)
    for run in ("a", "b"):
        for r in (1, 2):
            run_stage(RoundContext(RunDir(tmp_path / run), r, 0, NO_TENSORBOARD), Stage("noisy", noisy))
    assert caplog.text.count("a note from a loop") == 4
    info_once_per_round(log, "a note from a loop")
    info_once_per_round(log, "a note from a loop")
    assert caplog.text.count("a note from a loop") == 6
