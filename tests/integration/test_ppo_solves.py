"""PPO (rl=ppo with the task's settings from conf/rl_task) solves Cartpole balancing and Pendulum swing-up
on the nominal parameters, on CPU: the deterministic policy's mean return over 16 episodes passes a bar.

Bars: Cartpole 475 of the 500 an episode can earn (95 %); Pendulum -400 (gym's reward; uniform random
actions score about -1,300 on the nominal pendulum, PPO with these settings -280, -185 and -204 with seeds
0, 1, 2). A Cartpole run either balances (about 499) or collapses: 15 of 16 seeds reached the bar with torch
2.11 on the lent H200 machine's CPUs, seed 0 among the one that did not (docs/benchmarks.md), so Cartpole's claim
is that a training seed reaches the bar at a rate of 90 % or more: at least 2 of seeds 0, 1, 2 do (at a rate of
94 % the test fails about once in a hundred machines; at 50 %, one in two). About 25 s a run on a quiet 2-core
machine.
"""

import pytest

from bayessim_exp import registry
from bayessim_exp.components import build_components
from bayessim_exp.rl.standalone import StandaloneRounds
from bayessim_exp.run_config import check_run_config


@pytest.mark.slow
@pytest.mark.parametrize("task, bar, seeds, needed", [("Cartpole", 475.0, (0, 1, 2), 2), ("Pendulum", -400.0, (0,), 1)])
def test_ppo_solves_nominal_task(compose, tmp_path, task, bar, seeds, needed):
    import torch

    torch.set_num_threads(1)
    spec = registry.build("task", compose([f"task={task}"]).task).spec
    nominal_is_real = [f"task.real_params.{n}={v}" for n, v in zip(spec.names, spec.nominal)]
    returns = []
    for seed in seeds:
        if sum(r["mean"] >= bar for r in returns) >= needed:  # the claim holds whatever the seeds left would score
            break
        cfg = compose([f"task={task}", "rl=ppo", "rl.train_on=nominal", "rl.evaluate.video_steps=0", f"seed={seed}",
                       *nominal_is_real])
        comp = build_components(cfg, check_run_config(cfg))
        rounds = StandaloneRounds(cfg, comp, comp.prior, tmp_path / f"seed{seed}")
        returns.append(rounds.rl.record(rounds.run_round(1))["surrogate_real_return"])
    assert sum(r["mean"] >= bar for r in returns) >= needed, returns
