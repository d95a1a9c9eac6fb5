"""The adversarial family: methods as data (``methods``: ``MethodSpec``, registered presets),
the discriminator loss and reward (``losses``), the trainer (``trainer``:
``AdversarialTrainer``), the appendix baselines' training phases (``phase``, ``bc``,
``cail``, ``firl``, ``ranking``) and what a trainer can serve (``method_checks``)."""
