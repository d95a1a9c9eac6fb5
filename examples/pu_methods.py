"""Two positive-unlabelled (PU) discriminators as presets a user could write: PU-GAIL and UID.

    python -m experiments.sweep \
        --methods gail,pngail,examples.pu_methods:pu_gail,examples.pu_methods:uid

Both read no confidences. Each is one of the two non-negative PU risks of
``pngail_jax.adversarial.losses`` (the core term they needed, ``docs/methods.md``):

- PU-GAIL (Xu & Denil, 2019, "Positive-unlabeled reward learning"): the demonstrations are
  the labelled (expert) class and the agent's rows unlabelled, a share ``pu_prior`` of them
  taken as expert-like;
- UID (Wang et al., 2023, as PN-GAIL's related work describes it: imperfect demonstrations as
  unlabelled data, after du Plessis et al.'s PU learning): the agent's rows are the labelled
  class and the demonstrations unlabelled, a share ``pu_agent_prior`` of them taken as
  agent-like (the non-optimal ones).

The priors are ours, 0.5 each: neither paper's value for these tasks is known here; a grid
axis sweeps them (``--grid pu_prior=0.3,0.5,0.7``).
"""

from pngail_jax.adversarial.methods import Preset

pu_gail = Preset(
    "PU-GAIL: demonstrations positive, the agent's rows unlabelled (non-negative PU risk)",
    "none",
    {"pu_coef": 1.0, "pu_prior": 0.5},
)

uid = Preset(
    "UID: the agent's rows labelled, the demonstrations unlabelled (non-negative PU risk)",
    "none",
    {"pu_agent_coef": 1.0, "pu_agent_prior": 0.5},
)
