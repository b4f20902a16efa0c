"""rl=none: no RL stage; rounds only refine the posterior."""

import dataclasses

from ..registry import register


@dataclasses.dataclass
class NoRLConfig:
    pass


@register("rl", "none", NoRLConfig)
def no_rl(cfg: NoRLConfig, **_: object) -> None:
    return None
