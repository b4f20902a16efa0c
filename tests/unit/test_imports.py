"""What a default run does not import: each of these costs a process a noticeable part of its start."""

from __future__ import annotations

import subprocess
import sys


def test_a_pipeline_process_fits_a_model_and_checks_mismatch_without_dynamo_scipy_stats_or_jax():
    # torch._dynamo (torch.optim imports it: 1.7 s here, 5.4 s on the H100 host; models/adam.py);
    # scipy.stats 0.3 s on top of scipy.optimize (which the MDN's spread calibration needs);
    # JAX and MJX 1.7 s on the development machine, needed only where sim=mjx runs
    code = ("import sys, torch; from bayessim_exp import api, registry; import bayessim_exp.pipeline; "
            "registry.load_builtins(); from bayessim_exp.diagnostics.mismatch import summaries_outside; "
            "cfg = api.compose(['model.max_epochs=2']); "
            "m = registry.build('model', cfg.model, theta_dim=2, x_dim=3); "
            "m.fit(torch.randn(300, 2), torch.randn(300, 3), seed=0); "
            "out = summaries_outside(torch.zeros(1, 3), torch.randn(100, 3), torch.randn(10, 3)); "
            "print(out['p_value'], *(name in sys.modules for name in ('torch._dynamo', 'scipy.stats', 'jax')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["[1.0]", "False", "False", "False"]
