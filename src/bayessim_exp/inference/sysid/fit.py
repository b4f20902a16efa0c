"""One sysid fit: mujoco.sysid's optimiser (mujoco.minimize's bounded Gauss-Newton / Levenberg-Marquardt with a
finite-difference Jacobian) on the replay residual, and sysid's confidence intervals at the estimate.

mujoco.sysid ships with mujoco but needs the optional dependencies of `mujoco[sysid]` (scipy, absl-py, colorama,
tabulate, ...); without them `import mujoco.sysid` succeeds and holds nothing, so `require_sysid` checks for what
this module uses and names the extra to install.
"""

from __future__ import annotations

import dataclasses
import io
import logging
import math
from types import ModuleType

import numpy as np
import scipy.special

from ...errors import ConfigError, DataError, PosteriorError
from .residual import ReplayResidual

log = logging.getLogger(__name__)

INTERVAL_ALPHA = 0.05  # sysid's default: the recorded intervals are 95 % ones


@dataclasses.dataclass
class SysidConfig:
    """method=sysid; defaults in conf/method/sysid.yaml."""

    max_iters: int  # iterations of each Gauss-Newton run
    starts: int  # Gauss-Newton runs per round: from the previous estimate, and from the best screened prior draws
    screen: int  # prior draws whose residuals pick the other starts
    fd_step: float  # finite-difference step as a fraction of each parameter's prior range
    min_noise_std: float  # floor on the residuals' noise standard deviation, in units of each observation's spread
    identified_below: float  # identified: the data alone give a standard deviation below this fraction of the prior's
    max_noise_std: float  # a fit whose noise estimate exceeds this (units of each observation's spread) failed
    observed: list[str] | None  # observation names fitted (partial observations); None: all

    def validate(self) -> None:
        if self.max_iters < 1:
            raise ConfigError(f"need max_iters >= 1, got {self.max_iters}")
        if self.starts < 1 or (self.starts > 1 and self.screen < self.starts - 1):
            raise ConfigError(f"need starts >= 1 and screen >= starts - 1, got starts={self.starts}, screen={self.screen}")
        if not 0 < self.fd_step < 0.1:
            raise ConfigError(f"fd_step is a fraction of the prior range in (0, 0.1), got {self.fd_step}")
        if not (self.min_noise_std > 0 and math.isfinite(self.min_noise_std)):  # 0: float32 rounding as the noise
            raise ConfigError(f"need a finite min_noise_std > 0, got {self.min_noise_std}")
        if not self.identified_below > 0:
            raise ConfigError(f"need identified_below > 0, got {self.identified_below}")
        if not self.max_noise_std > 0:
            raise ConfigError(f"need max_noise_std > 0, got {self.max_noise_std}")


def require_sysid() -> ModuleType:
    """mujoco.sysid with its optional dependencies, or a ConfigError saying how to install them."""
    from mujoco import sysid

    if not all(hasattr(sysid, name) for name in ("optimize", "calculate_intervals", "Parameter", "ParameterDict")):
        raise ConfigError("method=sysid needs the optional dependencies of mujoco.sysid: "
                          "pip install 'bayessim_exp[sysid]' (or 'mujoco[sysid]')")
    return sysid


@dataclasses.dataclass(frozen=True)
class SysidFit:
    """The estimate in unit coordinates of the prior box and what the covariance is built from."""

    estimate: np.ndarray  # u* [D]
    jacobian: np.ndarray  # dr/du at u* [R, D]
    residual: np.ndarray  # r(u*) [R]
    # sysid's standard deviations per unit of noise standard deviation, sqrt(diag (J^T J)^-1) [D], in unit coordinates;
    # inf where the data cannot identify the parameter (sysid's eigenvalue test)
    unit_noise_std: np.ndarray
    objectives: list[float]  # 0.5 |r|^2 per iteration

    @property
    def noise_var(self) -> float:
        """sysid's estimate of the residuals' noise variance: |r|^2 / (R - D), as in calculate_intervals."""
        return float(self.residual @ self.residual) / (self.residual.size - self.estimate.size)


def fit(residual: ReplayResidual, names: list[str], start: np.ndarray, cfg: SysidConfig) -> SysidFit:
    """Least squares of `residual` over u in [0, 1]^D from `start` [D]."""
    sysid = require_sysid()
    if residual.size <= len(names):
        raise DataError(f"sysid: {residual.size} observed values cannot determine {len(names)} parameters; record "
                        "longer or more real trajectories")
    params = sysid.ParameterDict()
    for name, u0 in zip(names, start):
        params.add(sysid.Parameter(name, float(u0), 0.0, 1.0))
    params.move_off_bounds()  # sysid's advice: a start on a bound can stall the bounded solver there

    def residual_fn(x: np.ndarray, _params) -> tuple[list[np.ndarray], None, None]:
        return [residual(x)], None, None

    start_r = residual(params.as_vector())
    if not np.isfinite(start_r).all():
        raise PosteriorError("sysid: the replays diverge at the starting parameters")
    trace = io.StringIO()  # the solver's per-iteration lines, logged at debug level instead of printed
    _, result = sysid.optimize(params, residual_fn, optimizer="mujoco", verbose=False, max_iters=cfg.max_iters,
                               eps=cfg.fd_step, output=trace)
    log.debug("sysid solver:\n%s", trace.getvalue())
    u = np.asarray(result.x, np.float64)
    r = residual(u)
    jac = np.asarray(result.jac, np.float64)
    if not (np.isfinite(r).all() and np.isfinite(jac).all()):
        raise PosteriorError("sysid: replays near the estimate diverge; its Jacobian is not finite")
    return SysidFit(u, jac, r, unit_noise_std(sysid, jac), [float(v) for v in result.extras["objective"]])


def unit_noise_std(sysid: ModuleType, jac: np.ndarray) -> np.ndarray:
    """sysid's confidence intervals as standard deviations at noise variance 1: calculate_intervals estimates the
    noise variance from the residuals it is given as |r|^2 / (R - D), so residuals of that norm make it 1 (the
    covariance is then scaled by the noise variance actually used, which may be floored)."""
    rows, dim = jac.shape
    unit = np.full(rows, math.sqrt((rows - dim) / rows))
    _, half_widths = sysid.calculate_intervals([unit], jac, alpha=INTERVAL_ALPHA)
    return np.asarray(half_widths, np.float64) / interval_quantile(rows, dim)


def interval_quantile(rows: int, dim: int) -> float:
    """Student's t quantile sysid's intervals are half-widths of (rows - dim degrees of freedom)."""
    return float(scipy.special.stdtrit(rows - dim, 1 - INTERVAL_ALPHA / 2))
