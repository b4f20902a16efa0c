"""PPO (rl=ppo with the task's settings from conf/rl_task) solves Cartpole balancing and Pendulum swing-up
on the nominal parameters, on CPU: the deterministic policy's mean return over 16 episodes passes a bar.

Bars: Cartpole 475 of the 500 an episode can earn (95 %); Pendulum -400 (gym's reward; uniform random
actions score about -1,300 on the nominal pendulum, PPO with these settings -280, -185 and -204 with seeds
0, 1, 2). About 25 s each on a quiet 2-core machine, up to 3 minutes when it is shared with other jobs.
"""

import pytest

from bayessim_exp import registry
from bayessim_exp.components import build_components
from bayessim_exp.rl.standalone import StandaloneRounds
from bayessim_exp.run_config import check_run_config


@pytest.mark.slow
@pytest.mark.parametrize("task, bar", [("Cartpole", 475.0), ("Pendulum", -400.0)])
def test_ppo_solves_nominal_task(compose, tmp_path, task, bar):
    import torch

    torch.set_num_threads(1)
    spec = registry.build("task", compose([f"task={task}"]).task).spec
    nominal_is_real = [f"task.real_params.{n}={v}" for n, v in zip(spec.names, spec.nominal)]
    cfg = compose([f"task={task}", "rl=ppo", "rl.train_on=nominal", "rl.evaluate.video_steps=0", *nominal_is_real])
    comp = build_components(cfg, check_run_config(cfg))
    rounds = StandaloneRounds(cfg, comp, comp.prior, tmp_path)
    ret = rounds.rl.record(rounds.run_round(1))["surrogate_real_return"]
    assert ret["mean"] >= bar, ret
