"""The jobs: each a whole piece of work callable from Python with a config, with its outputs,
progress, checkpoints and one-line refusals. In dependency order (each imports only those
before it):

- ``errors``: ``RunError``, the one-line refusal every job raises; ``refusals``, which turns
  an output claim's refusal into one.
- ``trainer_configs``: ``adversarial_config``, the one place a ``RunConfig`` becomes the
  trainer's static config (``sized_classifier``: the classifier's batch width).
- ``classify``: ``classify``, Table 1 and 5's classifiers on a demonstrations file.
- ``chunks``: the one chunk step (run a compiled chunk, fetch, join its metrics, time it,
  print its line, checkpoint), the loop over chunks, stopping at a checkpoint, resuming
  (``resumable_config``: the sealed config.json of a run to resume).
- ``seeds``: ``train_seeds``, a TRPO run of stacked seeds.
- ``make_demos_run``: a demonstration making's sealed config.json, the checks of its
  resume, and the kept policies a resume reads back.
- ``make_demos``: ``make_demonstrations``, imperfect demonstrations made from scratch
  (resumable from its last block).
- ``train_rl``: ``train_rl``, TRPO alone on an environment's true reward.
- ``compare_settings``: ``compare_settings``, run settings side by side (train_rl runs).
- ``build``: a sweep's environment, demonstrations (made once and cached), trainer and grid.
- ``record``: a sweep's config.json, its seal, and the checks of a resume.
- ``results``: a sweep's outputs, policies and ``RunResult``.
- ``sweep``: ``run(config, out)``, a sweep's lifecycle as named steps.

Nothing here parses flags: ``pngail_jax.programs`` turns flags into a config and calls one
job.
"""
