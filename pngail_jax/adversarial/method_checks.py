"""What a trainer can serve, checked on the host before a grid compiles: the methods against
the demonstrations and the training phases the trainer compiles, the label ratios against
the split. One place for both, so the run's build and a user's own trainer refuse the same
things with the same words (``AdversarialTrainer.check_methods`` / ``check_label_ratios``
call these with what the trainer holds)."""

from __future__ import annotations

import numpy as np

from pngail_jax.adversarial.methods import required_phases, resolve, trains_classifier
from pngail_jax.adversarial.ranking import RankingConfig, Trajectories
from pngail_jax.confidence import ClassifierConfig
from pngail_jax.demos import DemonstrationError


def check_methods(
    methods,
    has_confidence: bool,
    phases: tuple[str, ...],
    gradient_penalty: bool,
    trajectories: Trajectories | None,
    ranking: RankingConfig,
    classifier: bool = True,
) -> None:
    """Raises ``DemonstrationError`` naming the methods that need what the demonstrations do
    not carry (confidences; trajectories, of at least two confidences, long enough for
    T-REX's snippets), and ``ValueError`` naming those that need a phase, the gradient
    penalty or the confidence classifier (``classifier`` False: not compiled) the trainer
    does not compile."""
    readers = [name for name in methods if resolve(name).confidence_source != "none"]
    if not has_confidence and readers:
        raise DemonstrationError(
            f"the demonstrations carry no confidences, which {', '.join(readers)} read; "
            "give a confidence file, or run only methods that read none (gail, wgail)"
        )
    missing = [phase for phase in required_phases(methods) if phase not in phases]
    if missing:
        raise ValueError(
            f"methods {list(methods)} need the training phase(s) {missing}, which this "
            "trainer does not compile: AdversarialConfig(phases=required_phases(methods))"
        )
    penalised = [
        name for name in methods if resolve(name).coefficients.get("gradient_penalty_coef")
    ]
    if penalised and not gradient_penalty:
        raise ValueError(
            f"{', '.join(penalised)} use a gradient penalty, which this trainer does not "
            "compile: AdversarialConfig(gradient_penalty=True)"
        )
    classified = [name for name in methods if trains_classifier([name])]
    if classified and not classifier:
        raise ValueError(
            f"{', '.join(classified)} read the confidence classifier, which this trainer does "
            "not compile: AdversarialConfig(confidence_classifier=True)"
        )
    _check_rankings(methods, trajectories, ranking)


def _check_rankings(methods, trajectories: Trajectories | None, ranking: RankingConfig) -> None:
    rankers = [name for name in methods if resolve(name).confidence_source == "rankings"]
    if rankers and trajectories is None:
        raise DemonstrationError(
            f"{', '.join(rankers)} rank whole trajectories, but these demonstrations have "
            "no trajectory ids (the authors' MuJoCo files are rows, not trajectories; "
            "made sets and the authors' Pendulum file have them)"
        )
    if rankers and len(np.unique(np.asarray(trajectories.score))) < 2:
        raise DemonstrationError(
            f"{', '.join(rankers)} need trajectories of at least two confidences to rank"
        )
    length = ranking.snippet_length
    if "demo_rankings" in required_phases(methods) and ranking.skip_short_trajectories:
        long_enough = np.asarray(trajectories.lengths) >= length
        if len(np.unique(np.asarray(trajectories.score)[long_enough])) < 2:
            raise DemonstrationError(
                f"trex compares snippets of {length} steps, but fewer than two confidences "
                f"are among the trajectories of at least {length} steps"
            )


def check_label_ratios(
    label_ratios, num_demos: int, classifier: ClassifierConfig, num_allowed: int | None
) -> None:
    """Raises ``DemonstrationError`` when the demonstrations' ``labelled`` mask allows only
    ``num_allowed`` rows (None: no mask, or no confidences) and the largest ratio labels
    more, ``round(label_ratio * num_demos)``; ``ValueError`` when a ratio leaves no labelled
    or no unlabelled row of the ``num_demos``, or when the smallest needs a wider unlabelled
    classifier batch than ``classifier`` compiles."""
    for ratio in label_ratios:
        num_labelled = round(float(ratio) * num_demos)
        if not 0 < num_labelled < num_demos:
            raise ValueError(
                f"label ratio {float(ratio):g} labels {num_labelled} of {num_demos} rows; "
                "need at least one labelled and one unlabelled row"
            )
    largest = max(float(ratio) for ratio in label_ratios)
    requested = round(largest * num_demos)
    if num_allowed is not None and requested > num_allowed:
        raise DemonstrationError(
            f"label ratio {largest:g} of {num_demos} rows asks for {requested} labelled "
            f"rows, but the demonstrations' labelled mask allows only {num_allowed}"
        )
    smallest = min(float(ratio) for ratio in label_ratios)
    num_labelled = max(round(smallest * num_demos), 1)
    needed = classifier.unlabelled_rows_per_step(num_demos, num_labelled)
    if needed > classifier.unlabelled_batch_width:
        raise ValueError(
            f"label ratio {smallest:g} of {num_demos} rows needs {needed} unlabelled "
            "rows per classifier step (n_u // n_c), more than ClassifierConfig's "
            f"max_unlabelled_batch_size {classifier.max_unlabelled_batch_size}: raise it"
        )
