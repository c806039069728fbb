"""skidmc.analysis.skill: scores against closed forms, the references and the verdict."""

import math

import numpy as np
import pytest

from skidmc.analysis.skill import (
    COIN_BRIER,
    COIN_LOG_SCORE,
    plot_reliability,
    reliability,
    skill_scores,
)

# Every expected value below is a closed form evaluated in double precision; 1e-12 allows only
# summation rounding.
TOL = 1e-12


def test_a_coin_flip_scores_ln2_and_a_quarter_and_has_no_skill():
    s = skill_scores([0.5] * 4, [True, False, False, True])
    assert s.log_score == pytest.approx(math.log(2), abs=TOL)
    assert s.brier == pytest.approx(0.25, abs=TOL)
    # base rate 1/2 scores exactly as the coin: equal is not better
    assert s.log_score_base_rate == pytest.approx(math.log(2), abs=TOL)
    assert s.brier_base_rate == pytest.approx(0.25, abs=TOL)
    assert not s.log_skill and not s.brier_skill
    assert s.verdict("log").startswith("no skill")
    assert s.log_skill_score == pytest.approx(0.0, abs=TOL)


def test_closed_forms_of_the_scores_and_the_base_rate():
    p = np.array([0.9, 0.2, 0.6, 0.1, 0.3])
    went = np.array([True, False, True, False, False])
    s = skill_scores(p, went)
    p_out = np.array([0.9, 0.8, 0.6, 0.9, 0.7])
    assert s.log_score == pytest.approx(-np.mean(np.log(p_out)), abs=TOL)
    assert s.brier == pytest.approx(np.mean((p - went) ** 2), abs=TOL)
    f = 2 / 5
    assert s.base_rate == pytest.approx(f, abs=TOL)
    assert s.log_score_base_rate == pytest.approx(-(f * math.log(f) + (1 - f) * math.log(1 - f)),
                                                  abs=TOL)
    assert s.brier_base_rate == pytest.approx(f * (1 - f), abs=TOL)
    assert s.log_score_se == pytest.approx(np.std(-np.log(p_out), ddof=1) / math.sqrt(5),
                                           abs=TOL)
    assert s.log_skill and s.brier_skill and s.verdict("brier") == "skill"
    assert s.brier_skill_score == pytest.approx(1 - s.brier / (f * (1 - f)), abs=TOL)


def test_confident_and_wrong_is_no_skill_worse_than_both():
    # The quartz case in miniature: predictions that lean the wrong way.
    s = skill_scores([0.8, 0.8, 0.2, 0.2], [False, False, True, True])
    assert s.log_score == pytest.approx(-math.log(0.2), abs=TOL)
    assert s.log_score > COIN_LOG_SCORE and s.brier > COIN_BRIER
    assert s.verdict("log") == "no skill (not better than a coin flip or the base rate)"


def test_all_no_go_drops_make_the_base_rate_perfect():
    # Gold: every drop a no-go. The base rate (always 0) scores 0, so no prediction that gives
    # a go any chance beats it, and the skill score is undefined (nan), not a division by 0.
    s = skill_scores([0.01, 0.02, 0.05, 0.1], [False] * 4)
    assert s.log_score_base_rate == 0.0 and s.brier_base_rate == 0.0
    assert not s.log_skill
    assert s.verdict("log") == ("better than a coin flip; skill not measurable (every drop had "
                                "the same outcome)")
    assert math.isnan(s.brier_skill_score)


def test_a_certain_wrong_prediction_scores_infinity():
    s = skill_scores([0.0, 1.0], [True, True])
    assert math.isinf(s.log_score) and math.isnan(s.log_score_se)
    assert not s.log_skill


@pytest.mark.parametrize("p, went, word", [
    ([], [], "at least one drop"),
    ([0.5, 0.5], [True], "one per drop"),
    ([1.5], [True], "[0, 1]"),
    ([0.5], [2], "True/False"),
])
def test_bad_input_names_the_argument(p, went, word):
    with pytest.raises(ValueError, match=r"p_go|went") as err:
        skill_scores(p, went)
    assert word in str(err.value)


def test_reliability_groups_repeated_predictions_and_counts_every_drop():
    # Drops at two heights (as the report's quartz: 1.5 ft and 2.12 ft): two groups.
    p = [0.3] * 6 + [0.7] * 4
    went = [False] * 5 + [True] + [True] * 3 + [False]
    rows = reliability(p, went)
    assert [r["n"] for r in rows] == [6, 4]
    assert [r["n_go"] for r in rows] == [1, 3]
    assert rows[0]["observed"] == pytest.approx(1 / 6, abs=TOL)
    assert all(r["low"] <= r["observed"] <= r["high"] for r in rows)
    # Wilson interval of 1/6 at 90 %: closed form.
    z = 1.6448536269514722
    n, ph = 6, 1 / 6
    centre = (ph + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(ph * (1 - ph) / n + z * z / (4 * n * n))
    assert rows[0]["low"] == pytest.approx(centre - half, abs=1e-9)
    assert rows[0]["high"] == pytest.approx(centre + half, abs=1e-9)


def test_reliability_bins_many_distinct_predictions():
    p = np.linspace(0.05, 0.95, 12)
    rows = reliability(p, p > 0.5, bins=4)
    assert sum(r["n"] for r in rows) == 12
    assert len(rows) == 4
    assert all(0.0 <= r["predicted"] <= 1.0 for r in rows)


def test_plot_reliability_draws_every_bin(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = reliability([0.3] * 6 + [0.7] * 4, [False] * 5 + [True] * 4 + [False])
    fig, ax = plt.subplots()
    plot_reliability(ax, rows, title="quartz")
    labels = [t.get_text() for t in ax.texts]
    assert labels == ["1 goes in 6 drops", "3 goes in 4 drops"]
    fig.savefig(tmp_path / "r.png")
    plt.close(fig)
