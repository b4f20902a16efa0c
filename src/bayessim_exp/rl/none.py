"""rl=none: no RL stage; rounds only refine the posterior."""

import dataclasses


@dataclasses.dataclass
class NoRLConfig:
    pass


def no_rl(cfg: NoRLConfig, **_: object) -> None:
    return None
