"""Adam (Kingma & Ba 2015, L2 weight decay added to the gradient) without torch.optim.

torch.optim imports torch._dynamo when an optimiser is built (its add_param_group is wrapped to stay
out of compilation): seconds once per process (docs/benchmarks.md) for a run that never compiles. The arithmetic is torch.optim.Adam's: on a CPU its
single-tensor path (identical results), on a GPU its fused kernel with the step counts on the device,
so that the update can be captured in a CUDA graph.
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
            self._single_tensor_step(live)

    def _fused_step(self, live: list[int]) -> None:
        steps = [self.steps[i] for i in live]
        torch._foreach_add_(steps, 1)
        torch._fused_adam_([self.params[i] for i in live], [self.params[i].grad for i in live],
                           [self.exp_avg[i] for i in live], [self.exp_avg_sq[i] for i in live], [], steps,
                           lr=self.lr, beta1=BETA1, beta2=BETA2, weight_decay=self.weight_decay, eps=EPS,
                           amsgrad=False, maximize=False)

    def _single_tensor_step(self, live: list[int]) -> None:
        for i in live:
            param, grad, exp_avg, exp_avg_sq = self.params[i], self.params[i].grad, self.exp_avg[i], self.exp_avg_sq[i]
            self.steps[i] += 1
            bias_correction1 = 1 - BETA1 ** self.steps[i]
            bias_correction2_sqrt = (1 - BETA2 ** self.steps[i]) ** 0.5
            if self.weight_decay != 0:
                grad = grad.add(param, alpha=self.weight_decay)
            exp_avg.lerp_(grad, 1 - BETA1)
            exp_avg_sq.mul_(BETA2).addcmul_(grad, grad, value=1 - BETA2)
            denom = (exp_avg_sq.sqrt() / bias_correction2_sqrt).add_(EPS)
            param.addcdiv_(exp_avg, denom, value=-(self.lr / bias_correction1))
