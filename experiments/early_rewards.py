"""``python -m experiments.early_rewards`` from a checkout: runs pngail_jax.programs.early_rewards
(installed as the command ``pngail-early-rewards``)."""

from pngail_jax.programs.early_rewards import main

if __name__ == "__main__":
    main()
