"""What a default run does not import: each of these costs a process a noticeable part of its start."""

from __future__ import annotations

import subprocess
import sys


def test_building_components_and_the_mismatch_check_do_not_import_scipy_stats_or_jax():
    # scipy.stats takes 0.3 s on top of scipy.optimize (which the MDN's spread calibration needs);
    # JAX and MJX 1.7 s on the development machine, needed only where sim=mjx runs
    code = ("import sys, torch; from bayessim_exp import registry; import bayessim_exp.pipeline; "
            "registry.load_builtins(); from bayessim_exp.diagnostics.mismatch import summaries_outside; "
            "out = summaries_outside(torch.zeros(1, 3), torch.randn(100, 3)); "
            "print(out['p_value'], 'scipy.stats' in sys.modules, 'jax' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["[1.0]", "False", "False"]
