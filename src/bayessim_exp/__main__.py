"""`python -m bayessim_exp [overrides]`: compose the Hydra config and run the pipeline."""

import sys

import hydra
from omegaconf import DictConfig


@hydra.main(version_base="1.3", config_path="conf", config_name="config")
def _app(cfg: DictConfig) -> None:
    from hydra.core.hydra_config import HydraConfig

    from .errors import ConfigError, DataError, PosteriorError, TrainingError
    from .pipeline import run

    try:
        results = run(cfg, HydraConfig.get().runtime.output_dir)
    except (ConfigError, DataError, PosteriorError, TrainingError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    last = results["rounds"][-1]
    print(f"{results['run_name']}: {len(results['rounds'])} rounds -> {HydraConfig.get().runtime.output_dir}")
    for name in results["param_names"][:8]:
        print(f"  {name:>20s}: {last['posterior_mean'][name]:.4g} +- {last['posterior_std'][name]:.3g}"
              + (f"  (true {results['true_params'][name]:.4g})" if results["true_params"] else ""))
    if last["log_prob_gain"] is not None:
        print(f"  log p(true | real) - log p(true) = {last['log_prob_gain']:.2f} nats")


def main() -> None:
    _app()


if __name__ == "__main__":
    main()
