"""What the posterior model is fitted in (method.parameter_space): probit space, the prior's CDFs mapped through
the normal quantile (distributions/probit.py; posteriors stay on the box), or parameter units."""

from __future__ import annotations

import logging
from typing import Literal

from ...distributions.base import ParameterDistribution
from ...distributions.probit import ProbitTransform
from ...errors import ConfigError

log = logging.getLogger(__name__)

# probit; box: parameter units; auto: probit where the prior allows it (independent, on a box), else box
ParameterSpace = Literal["auto", "probit", "box"]


def probit_transform(space: str, prior: ParameterDistribution) -> ProbitTransform | None:
    """parameter_space probit or auto: the transform, None where auto falls back to parameter units."""
    try:
        return ProbitTransform(prior)
    except ValueError as exc:
        if space == "auto":
            log.info("method.parameter_space=auto: %s; fitting in parameter units", exc)
            return None
        raise ConfigError(f"method.parameter_space=probit: {exc}; set method.parameter_space=box (or auto)") from None
