"""What a trainer can serve (pngail_jax.adversarial.method_checks), checked on the host with no
trainer: label ratios against the split and the classifier's batch, methods against the data."""

import pytest

from pngail_jax.adversarial.method_checks import check_label_ratios, check_methods
from pngail_jax.adversarial.ranking import RankingConfig
from pngail_jax.confidence import ClassifierConfig
from pngail_jax.demos import DemonstrationError


def test_a_ratio_must_leave_a_labelled_and_an_unlabelled_row():
    classifier = ClassifierConfig()
    check_label_ratios([0.2, 0.5], 100, classifier, None)  # 20 and 50 of 100: fine
    with pytest.raises(ValueError, match="labels 0 of 100 rows"):
        check_label_ratios([0.004], 100, classifier, None)
    with pytest.raises(ValueError, match="labels 100 of 100 rows"):
        check_label_ratios([0.2, 0.999], 100, classifier, None)


def test_a_labelled_mask_caps_the_largest_ratio():
    classifier = ClassifierConfig()
    check_label_ratios([0.1, 0.15], 40, classifier, 6)  # round(0.15 * 40) = 6 rows: allowed
    with pytest.raises(DemonstrationError, match="asks for 8 labelled rows.*allows only 6"):
        check_label_ratios([0.1, 0.2], 40, classifier, 6)


def test_the_smallest_ratio_must_fit_the_classifiers_unlabelled_batch():
    narrow = ClassifierConfig(max_unlabelled_batch_size=4)
    check_label_ratios([0.2], 100, narrow, None)  # n_u // n_c = 80 // 20 = 4
    with pytest.raises(ValueError, match="needs 9 unlabelled rows per classifier step"):
        check_label_ratios([0.1], 100, narrow, None)  # 90 // 10 = 9


def test_methods_that_read_confidences_need_them_and_their_phases():
    ranking = RankingConfig()
    check_methods(["gail", "wgail"], False, (), False, None, ranking)
    with pytest.raises(DemonstrationError, match="carry no confidences, which pngail read"):
        check_methods(["gail", "pngail"], False, (), False, None, ranking)
    with pytest.raises(ValueError, match=r"need the training phase\(s\) \['cail'\]"):
        check_methods(["cail"], True, (), False, None, ranking)
    with pytest.raises(DemonstrationError, match="rank whole trajectories"):
        check_methods(["cail"], True, ("cail",), False, None, ranking)
