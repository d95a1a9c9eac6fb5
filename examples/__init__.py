"""Methods defined outside the package, through its public route
(``pngail_jax.adversarial.methods``'s ``Preset``, named ``examples.<module>:<preset>``); not
installed with the package."""
