"""The parts a run is made of, at the bottom of the house (issue 74, item 1): the field checks
every config shares (``validation``); the parts, each default and check written once and
importing no JAX: the learner (``learner``: ``LearnerConfig``, names, Fisher forms,
``RolloutConfig``, ``TRPOConfig``, ``PPOConfig``, the hyperparameters' ranges), the
demonstrations (``demonstrations``: ``DemonstrationsConfig``), the budget (``budget``), the grid
(``grid_axes``), the output (``output``), the classifier (``classifier``), the methods
(``methods``, over the plain table ``presets``) and the authors' files (``released_files``);
the task (``task``), the per-environment settings (``settings``) and a training job's shared
fields (``training``: env, settings, budget, learner, checked once), which read the
environments' names; a sweep's ``RunConfig`` and its checks (``run_config``,
``run_config_checks``) and what a saved ``config.json`` keeps around it (``saved``). config/
imports nothing above it: ``jobs.trainer_configs`` turns a ``RunConfig`` into the trainer's
static config. Nothing is imported here."""
