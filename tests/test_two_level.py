"""A key uncertain at two levels: an epistemic level times an aleatory factor (friction: a fixed
but poorly known mean per finish, times drop-to-drop scatter).

The rule (``skidmc.ensemble.study``, module docstring): a scene's entry replaces the study-wide
entry of the same key and kind; an entry of each kind combines, the aleatory one being a relative
factor on the epistemic value; where a scene has only the study-wide factor, it applies to the
nominal value.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.stats

from skidmc.ensemble.sampling import StudySampler, transform
from skidmc.ensemble.study import U_TAIL, StudyError, parse_study
from skidmc.ensemble.study_model import aleatory_factor_column

TWO_LEVEL = """
[study]
name = "two-level"
[[scenes]]
name = "quartz"
preset = "paper-quartz"
[scenes.uncertain.mu]
distribution = "uniform"
loc = 0.2
scale = 0.1
kind = "epistemic"
source = "test"
[[scenes]]
name = "gold"
preset = "paper-gold"
[uncertain.mu]
distribution = "lognorm"
s = 0.1
relative = true
kind = "aleatory"
source = "test"
[design]
method = "mc"
n = 16
n_epistemic = 4
seed = 3
"""


def test_columns_kinds_and_scene_entries():
    study = parse_study(TWO_LEVEL)
    factor = aleatory_factor_column("mu")
    assert study.keys == ("mu", factor)
    assert [study.kind(k) for k in study.keys] == ["epistemic", "aleatory"]
    quartz, gold = study.scenes
    assert quartz.uncertain["mu"].kind == "epistemic" and quartz.factors["mu"].relative
    assert "mu" not in gold.uncertain and gold.factors["mu"].params == (("s", 0.1),)
    assert study.nested and study.n_rows == 4 * 16


def test_value_is_the_epistemic_level_times_the_aleatory_factor():
    study = parse_study(TWO_LEVEL)
    u = np.array([[0.25, 0.5], [0.75, 0.9], [0.5, 0.1]])
    quartz, gold = transform(study, u)
    level = 0.2 + 0.1 * u[:, 0]                           # uniform(loc 0.2, scale 0.1)
    factor = scipy.stats.lognorm(0.1).ppf(u[:, 1])
    # Same operations as the sampler (ppf, one product): equal to the last bit; rtol 1e-15 only
    # allows a different rounding order of scipy's ppf.
    np.testing.assert_allclose(quartz["mu"], level * factor, rtol=1e-15)
    np.testing.assert_allclose(gold["mu"], 0.117 * factor, rtol=1e-15)  # gold's nominal mu


def test_every_epistemic_draw_meets_the_same_aleatory_factors():
    study = parse_study(TWO_LEVEL)
    quartz, gold = StudySampler(study).draw(0, study.n_rows)
    mu = quartz["mu"].reshape(4, 16)
    # The ratio of two epistemic draws is constant over the aleatory draws: the factor is shared
    # (common random numbers) and only the level differs.
    ratio = mu[1] / mu[0]
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-12)  # rounding of two products only
    assert np.unique(np.round(ratio, 12)).size == 1 and not np.isclose(ratio[0], 1.0)
    np.testing.assert_array_equal(gold["mu"].reshape(4, 16)[0], gold["mu"].reshape(4, 16)[3])
    # Every value stays inside the products of the checked tail quantiles.
    lo = 0.2 * scipy.stats.lognorm(0.1).ppf(U_TAIL)
    hi = 0.3 * scipy.stats.lognorm(0.1).ppf(1 - U_TAIL)
    assert lo <= mu.min() and mu.max() <= hi


def test_scene_entry_of_the_same_kind_still_replaces_the_study_entry():
    text = TWO_LEVEL.replace('kind = "epistemic"\n', "").replace("n_epistemic = 4\n", "")
    study = parse_study(text)
    assert study.keys == ("mu",) and not study.nested
    quartz, gold = study.scenes
    assert quartz.uncertain["mu"].name == "uniform" and not quartz.factors
    assert gold.uncertain["mu"].name == "lognorm" and not gold.factors


def test_study_wide_epistemic_level_with_a_scene_factor():
    text = TWO_LEVEL.replace(
        '[scenes.uncertain.mu]\ndistribution = "uniform"\nloc = 0.2\nscale = 0.1\n'
        'kind = "epistemic"',
        '[scenes.uncertain.mu]\ndistribution = "lognorm"\ns = 0.05\nrelative = true\n'
        'kind = "aleatory"').replace(
        '[uncertain.mu]\ndistribution = "lognorm"\ns = 0.1\nrelative = true\n'
        'kind = "aleatory"',
        '[uncertain.mu]\ndistribution = "uniform"\nloc = 0.9\nscale = 0.2\nrelative = true\n'
        'kind = "epistemic"')
    study = parse_study(text)
    quartz, gold = study.scenes
    assert quartz.uncertain["mu"].kind == "epistemic" and quartz.factors["mu"].params == (
        ("s", 0.05),)
    assert gold.uncertain["mu"].kind == "epistemic" and not gold.factors
    u = np.array([[0.5, 0.8]])
    q, g = transform(study, u)
    np.testing.assert_allclose(q["mu"], 0.132 * 1.0 * scipy.stats.lognorm(0.05).ppf(0.8),
                               rtol=1e-15)  # quartz nominal 0.132 x level 1.0 x factor
    np.testing.assert_allclose(g["mu"], 0.117 * 1.0, rtol=1e-15)


def test_two_level_without_n_epistemic_is_refused_naming_the_key():
    with pytest.raises(StudyError, match="mu are epistemic") as info:
        parse_study(TWO_LEVEL.replace("n_epistemic = 4\n", ""))
    assert info.value.key == "design.n_epistemic"


def test_a_run_stores_the_combined_values(tmp_path):
    from conftest import fake_height

    from skidmc.ensemble.run import run_study
    from skidmc.ensemble.storage import open_ensemble

    study = parse_study(TWO_LEVEL.replace("n = 16", "n = 4"))
    path = run_study(study, tmp_path / "e.h5", workers=1, progress=False, solver=fake_height)
    ds = open_ensemble(path)
    assert ds.attrs["design"]["keys"] == ["mu", "mu:aleatory_factor"]
    assert ds.attrs["design"]["kinds"] == ["epistemic", "aleatory"]
    quartz, gold = StudySampler(study).draw(0, study.n_rows)
    np.testing.assert_array_equal(ds["mu"].sel(scene="quartz").values.ravel(), quartz["mu"])
    np.testing.assert_array_equal(ds["mu"].sel(scene="gold").values.ravel(), gold["mu"])
