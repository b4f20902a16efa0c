"""Adam (Kingma & Ba 2015, L2 weight decay added to the gradient) without torch.optim.

torch.optim imports torch._dynamo when an optimiser is built (its add_param_group is wrapped to stay
out of compilation): seconds once per process (docs/benchmarks.md) for a run that never compiles. The arithmetic
is torch.optim.Adam's: on a CPU its single-tensor arithmetic (identical results, one torch._foreach_* call per
operation), on a GPU its fused kernel with the step counts on the device, so that the update can be captured in a
CUDA graph.
"""

from __future__ import annotations

import torch

BETA1, BETA2, EPS = 0.9, 0.999, 1e-8  # torch.optim.Adam's defaults


class Adam:
    def __init__(self, params: list[torch.Tensor], lr: float, weight_decay: float = 0.0, capturable: bool = False):
        self.params, self.lr, self.weight_decay, self.capturable = list(params), lr, weight_decay, capturable
        self.exp_avg = [torch.zeros_like(p) for p in self.params]
        self.exp_avg_sq = [torch.zeros_like(p) for p in self.params]
        # one count per tensor (a tensor that got no gradient skips its step): on the device for the fused kernel
        self.steps = [torch.zeros((), dtype=torch.float32, device=p.device) if capturable else 0 for p in self.params]

    def zero_grad(self) -> None:
        for p in self.params:
            p.grad = None

    @torch.no_grad()
    def step(self) -> None:
        live = [i for i, p in enumerate(self.params) if p.grad is not None]
        if self.capturable:
            self._fused_step(live)
        else:
            self._foreach_step(live)

    def _fused_step(self, live: list[int]) -> None:
        steps = [self.steps[i] for i in live]
        torch._foreach_add_(steps, 1)
        torch._fused_adam_([self.params[i] for i in live], [self.params[i].grad for i in live],
                           [self.exp_avg[i] for i in live], [self.exp_avg_sq[i] for i in live], [], steps,
                           lr=self.lr, beta1=BETA1, beta2=BETA2, weight_decay=self.weight_decay, eps=EPS,
                           amsgrad=False, maximize=False)

    def _foreach_step(self, live: list[int]) -> None:
        """torch.optim.Adam's single-tensor arithmetic, each operation applied to every live tensor at once
        (torch._foreach_*: the same values, one call per operation instead of one per tensor and operation)."""
        for i in live:
            self.steps[i] += 1
        params, exp_avgs, exp_avg_sqs = ([group[i] for i in live] for group in (self.params, self.exp_avg, self.exp_avg_sq))
        grads = [p.grad for p in params]
        if self.weight_decay != 0:
            grads = torch._foreach_add(grads, params, alpha=self.weight_decay)
        torch._foreach_lerp_(exp_avgs, grads, 1 - BETA1)
        torch._foreach_mul_(exp_avg_sqs, BETA2)
        torch._foreach_addcmul_(exp_avg_sqs, grads, grads, value=1 - BETA2)
        denoms = torch._foreach_sqrt(exp_avg_sqs)
        torch._foreach_div_(denoms, [(1 - BETA2 ** self.steps[i]) ** 0.5 for i in live])
        torch._foreach_add_(denoms, EPS)
        torch._foreach_addcdiv_(params, exp_avgs, denoms, [-(self.lr / (1 - BETA1 ** self.steps[i])) for i in live])
