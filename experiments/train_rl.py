"""``python -m experiments.train_rl`` from a checkout: runs pngail_jax.programs.train_rl
(installed as the command ``pngail-train-rl``)."""

from pngail_jax.programs.train_rl import main

if __name__ == "__main__":
    main()
