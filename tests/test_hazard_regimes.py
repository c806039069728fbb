"""The hazard study's claims: surfaces outside the model, assumptions, geometry, angle scales.

On the closed-form stand-in of tests/test_handling.py (ln H_c linear in the logs of mu, phi,
sigma, Q; every input log-normal, so P(reaction | surface) = Phi(-m_s / s_tot) exactly):

* a surface the model does not describe (elastic rubber) is never run, is not in P and is not
  counted as "no reaction": its weight is reported as an unmodelled share with the bound
  [P, P + w] (issue 39 item 4, issue 42 item 3);
* the summary lists the study file's assumptions and every distribution's source;
* the alternative (pendulum) geometry is estimated on scenes configured for it;
* P at other angle scales, from the same samples reweighted, agrees with the closed form and
  with a direct run of the study at that scale.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats
from test_handling import MEDIAN_LOG, NOT_FAILED, S_TOTAL, STUDY, StandIn

from skidmc.ensemble.hazard_study import load_hazard_study, parse_hazard_study
from skidmc.ensemble.study_model import StudyError
from skidmc.workflows.hazard import run_hazard_study

ROOT = Path(__file__).resolve().parents[1]

# The stand-in's pendulum geometry: ln H_c higher by this much (any shift the test can see).
PENDULUM_SHIFT = 0.4
WEIGHTS = {"concrete": 0.6, "oak": 0.3}
RUBBER = 0.1
ASSUMPTIONS = ["First impact of a bare billet only.", "Surface weights are a judgement."]

RUBBER_SURFACE = """
[[hazard.surface]]
material = "rubber"
weight = 0.1
source = "test: mats"
outside_model = "elastic: the plastic-contact model does not describe it"
[hazard.surface.friction]
distribution = "lognorm"
s = 0.2
scale = 0.2
source = "test"

[hazard.billet.flow_stress]"""

EXTRA = """
[hazard.alternatives]
configuration = "pendulum"
angle_scales = ["15 deg", "26 deg"]

[hazard.estimator]"""


def study_text(with_rubber: bool = True, extra: bool = True, draws: int = 4) -> str:
    text = STUDY.replace("weight = 0.7", "weight = 0.6")
    if with_rubber:
        text = text.replace("\n[hazard.billet.flow_stress]", RUBBER_SURFACE, 1)
    else:
        text = text.replace("weight = 0.6", "weight = 0.7")
    if extra:
        text = text.replace("\n[hazard.estimator]", EXTRA, 1)
    text = text.replace('description = "closed-form check"',
                        'description = "closed-form check"\nassumptions = '
                        + repr(ASSUMPTIONS).replace("'", '"'))
    return text.replace("epistemic_draws = 4", f"epistemic_draws = {draws}")


class GeometryStandIn(StandIn):
    """The stand-in, which also refuses (fails) an elastic target the way the solver does and
    records it, and shifts ln H_c under the pendulum geometry."""

    def __init__(self):
        super().__init__()
        self.elastic_calls = 0
        self.configurations = set()

    def __call__(self, columns, solver_options, *, base, workers=None):
        n = len(next(iter(columns.values())))
        self.configurations.add(base.configuration)
        if base.target_hardness == 0.0:  # the registry's rubber ("elastic")
            self.elastic_calls += 1
            import types
            return types.SimpleNamespace(
                critical_height=np.full(n, np.nan), status=np.full(n, "failed", dtype=object),
                failure_reason=np.full(n, "SceneError: elastic target", dtype=object))
        res = super().__call__(columns, solver_options, base=base, workers=workers)
        if base.configuration == "pendulum":
            res.critical_height = res.critical_height * math.exp(PENDULUM_SHIFT)
        return res


def exact(surface: str, shift: float = 0.0) -> float:
    return NOT_FAILED * stats.norm.sf((MEDIAN_LOG[surface] + shift) / S_TOTAL)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    solver = GeometryStandIn()
    out = tmp_path_factory.mktemp("regimes")
    result = run_hazard_study(parse_hazard_study(study_text()), out, solver=solver)
    return result, solver, out


def test_shipped_study_states_each_surface_regime():
    study = load_hazard_study(ROOT / "studies" / "hazard-handling.toml")
    regimes = {s.material: s.regime for s in study.surfaces}
    # concrete (6800 psi) and oak (60 MPa) lie below the billet's 28,000 psi flow stress even at
    # the sampled flow stress's 1e-9 quantile; steel and glass are rigid; rubber is elastic.
    assert regimes == {"concrete": "yielding", "steel": "rigid", "oak": "yielding",
                       "rubber": "outside", "soda-lime-glass": "rigid"}
    concrete = next(s for s in study.surfaces if s.material == "concrete")
    assert "6800 psi" in concrete.regime_note and "ACI 318" in concrete.regime_note
    assert study.unmodelled_weight == pytest.approx(0.13)
    assert study.alternative_configuration == "pendulum"
    assert [dict(d.params)["scale"] for d in study.angle_alternatives] == [5.0, 15.0, 20.0]
    assert len(study.assumptions) >= 10


def test_elastic_surface_without_outside_model_is_refused():
    text = study_text().replace(
        'outside_model = "elastic: the plastic-contact model does not describe it"\n', "")
    with pytest.raises(StudyError) as info:
        parse_hazard_study(text)
    assert info.value.key == "hazard.surface[2].material" or "rubber" in str(info.value)
    assert "elastic" in str(info.value) and "outside_model" in str(info.value)


@pytest.mark.parametrize("old, new, key", [
    ('configuration = "pendulum"', 'configuration = "sideways"',
     "hazard.alternatives.configuration"),
    ('configuration = "pendulum"', 'configuration = "vertical"',
     "hazard.alternatives.configuration"),
    ('angle_scales = ["15 deg", "26 deg"]', 'angle_scales = ["15 m"]',
     "hazard.alternatives.angle_scales"),
])
def test_bad_alternatives_name_their_key(old, new, key):
    with pytest.raises(StudyError) as info:
        parse_hazard_study(study_text().replace(old, new))
    assert info.value.key.startswith(key)


def test_bad_assumptions_refused():
    with pytest.raises(StudyError) as info:
        parse_hazard_study(study_text().replace(repr(ASSUMPTIONS).replace("'", '"'), '[""]'))
    assert info.value.key == "hazard.assumptions"


def test_refused_surface_is_not_counted_as_no_reaction(run):
    result, solver, _ = run
    assert solver.elastic_calls == 0  # never sent to the solver
    assert result.failed > 0  # the stand-in's heavy billets: those are failures, bounded
    rubber = next(s for s in result.surfaces if s.material == "rubber")
    assert rubber.regime == "outside" and math.isnan(rubber.conditional)
    assert [s.material for s in result.surfaces] == ["concrete", "oak", "rubber"]
    total = sum(WEIGHTS[s] * exact(s) for s in WEIGHTS)
    # P holds the modelled surfaces only (their weights 0.9), within its 95 % interval.
    assert result.interval[0] <= total <= result.interval[1]
    assert result.unmodelled_weight == pytest.approx(RUBBER)
    assert result.bounds == (result.probability, pytest.approx(result.probability + RUBBER))
    assert result.conditional_modelled == pytest.approx(result.probability / (1 - RUBBER))
    # no rubber sample anywhere: the epistemic loop skipped it too
    assert all(s.runs == 0 for s in result.surfaces if s.material == "rubber")


def test_summary_states_regimes_bound_and_assumptions(run):
    result, _, out = run
    text = (out / "summary.md").read_text()
    assert "## Assumptions" in text and "Notes: none" not in text
    for a in ASSUMPTIONS:
        assert f"- {a}" in text
    study = parse_hazard_study(study_text())
    for d in (study.drop_height, study.angle, *study.billet.values(),
              *study.epistemic.values(), *(s.friction for s in study.surfaces)):
        assert d.describe() in text
    assert "Outside the model: rubber (10% of accidents)" in text
    assert f"[{result.bounds[0]:.3g}, {result.bounds[1]:.3g}]" in text
    assert "| rubber | outside the model |" in text
    assert "| concrete | yielding |" in text


def test_pendulum_alternative_on_pendulum_scenes(run):
    result, solver, out = run
    assert solver.configurations == {"vertical", "pendulum"}
    a = result.alternative
    want = sum(WEIGHTS[s] * exact(s, shift=PENDULUM_SHIFT) for s in WEIGHTS)
    lo, hi = a["interval"]
    assert lo <= want <= hi  # its own 95 % interval
    assert a["probability"] < result.probability  # the shift raises H_c
    assert result.runs["alternatives"] >= a["runs"] > 0
    assert "## Geometry: vertical drop against pendulum" in (out / "summary.md").read_text()


def _scale_shift(scale_deg: float) -> float:
    # ln phi = ln(scale) + 0.2 Z, and ln H_c has -1.5 ln(phi / 20 deg): m_s moves by this.
    return -1.5 * math.log(scale_deg / 20.0)


def test_angle_scales_reweighted_against_closed_form_and_a_direct_run(run):
    result, _, _ = run
    by_scale = {a["scale_deg"]: a for a in result.angle_scales}
    assert set(by_scale) == {20.0, 15.0, 26.0}
    assert by_scale[20.0]["study"]
    assert by_scale[20.0]["probability"] == pytest.approx(result.probability, rel=1e-9)
    for scale in (15.0, 26.0):
        a = by_scale[scale]
        want = sum(WEIGHTS[s] * exact(s, shift=_scale_shift(scale)) for s in WEIGHTS)
        # 3 standard errors of the reweighted estimate: a false alarm under 0.3 % per scale.
        assert abs(a["probability"] - want) <= 3 * a["cov"] * a["probability"], scale
        assert a["cov"] < 0.3  # the samples cover these scales
    # A direct run of the study at 26 deg (fresh samples, no epistemic loop): the two
    # estimates differ by less than 3 combined standard errors.
    text = study_text(extra=False, draws=0).replace('scale = "20 deg"', 'scale = "26 deg"')
    direct = run_hazard_study(parse_hazard_study(text), None, solver=GeometryStandIn())
    a = by_scale[26.0]
    se = math.hypot(a["cov"] * a["probability"], direct.cov * direct.probability)
    assert abs(a["probability"] - direct.probability) <= 3 * se
    assert a["probability"] > result.probability  # wider angles, more reactions


def test_angle_band_brackets_within_draws(run):
    result, _, _ = run
    for a in result.angle_scales:
        assert a["band_low"] <= a["band_high"]
        # the alternative's mass beyond the study's 1e-9..1-1e-9 angle quantiles, on the
        # modelled surfaces' share of accidents (closed form of two log-normals)
        z = stats.norm.isf(1e-9)
        shift = math.log(a["scale_deg"] / 20.0) / 0.2
        want = (stats.norm.sf(z - shift) + stats.norm.cdf(-z - shift)) * (1 - RUBBER)
        assert a["uncovered"] == pytest.approx(want, rel=1e-6)


def test_committed_result_is_of_the_shipped_study_and_states_its_claims():
    # results/hazard-handling/ is committed: it must be the run of the study file as shipped
    # (same SHA-256), with the regimes, the unmodelled share, the alternatives and assumptions.
    import json

    folder = ROOT / "results" / "hazard-handling"
    study = load_hazard_study(ROOT / "studies" / "hazard-handling.toml")
    data = json.loads((folder / "summary.json").read_text())
    assert data["study"]["sha256"] == study.sha256
    assert data["unmodelled_weight"] == pytest.approx(study.unmodelled_weight)
    assert data["bounds"][1] == pytest.approx(data["probability"] + study.unmodelled_weight)
    assert data["alternative"]["configuration"] == "pendulum"
    assert [a["scale_deg"] for a in data["angle_scales"]] == [10.0, 5.0, 15.0, 20.0]
    text = (folder / "summary.md").read_text()
    for a in study.assumptions:
        assert f"- {a}" in text
    assert "| rubber | outside the model |" in text


def test_categorical_form_never_runs_an_outside_surface():
    # The single-input form (surface as a categorical input, for the generic methods): rows on
    # the outside surface get H_c = inf without a solver call.
    from skidmc.workflows.hazard import categorical_critical_height

    solver = GeometryStandIn()
    study = parse_hazard_study(study_text(extra=False, draws=0))
    critical_height, marginals, names = categorical_critical_height(study, solver=solver)
    rng = np.random.default_rng(3)
    x = np.column_stack([m.rvs(size=400, random_state=rng) for m in marginals])
    h = critical_height(x)
    rubber = np.rint(x[:, 0]).astype(int) == 2
    assert rubber.any() and np.all(np.isinf(h[rubber]))
    assert solver.elastic_calls == 0
