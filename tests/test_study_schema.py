"""The declared schemas of the study formats (skidmc.ensemble.study_schema): the models that
load every kind's files, exported per kind into docs/schemas and kept current; every shipped
study validates against its kind's model and exported schema, every malformed one fails it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from pydantic import ValidationError

from skidmc.ensemble.study_schema import SCHEMAS, json_schema
from skidmc.workflows.registry import kind_of_file

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
STUDIES = sorted((ROOT / "studies").glob("*.toml"))


@pytest.mark.parametrize("kind", sorted(SCHEMAS))
def test_exported_schema_is_current(kind):
    # Regenerate with: python -c "from skidmc.ensemble.study_schema import json_schema as j;
    # open('docs/schemas/KIND.json', 'w').write(j('KIND'))"
    path = ROOT / "docs" / "schemas" / f"{kind}.json"
    # Compared as JSON values, not text: pydantic versions write 1 or 1.0 for the same bound
    # (2.10 and 2.13 differ so); from pydantic 2.10, the lower bound, the values agree.
    assert json.loads(path.read_text()) == json.loads(json_schema(kind)), f"{path} is stale"
    assert json.loads(path.read_text())["title"] == f"skidmc {kind} study file"


@pytest.mark.parametrize("path", STUDIES, ids=[p.stem for p in STUDIES])
def test_every_shipped_study_validates_against_its_kind(path):
    kind = kind_of_file(path)
    SCHEMAS[kind].model_validate(tomllib.loads(path.read_text()))
    jsonschema = pytest.importorskip("jsonschema")  # what an editor does with the file
    jsonschema.validate(tomllib.loads(path.read_text()),
                        json.loads((ROOT / "docs" / "schemas" / f"{kind}.json").read_text()))


MALFORMED = sorted((ROOT / "tests" / "malformed_studies").glob("*.toml"))
# Refused before a model is chosen: the TOML itself, or the kind the file names.
BEFORE_THE_MODEL = {"toml_syntax", "study_kind_unknown"}


@pytest.mark.parametrize("path", MALFORMED, ids=[p.stem for p in MALFORMED])
def test_the_kinds_model_alone_refuses_every_malformed_study(path):
    # The models are the loader: validating the document with the kind's model (what an
    # editor's schema check and `skidmc run` share) refuses every mistake of the corpus,
    # those of meaning (units, physical ranges, materials) as well as those of structure.
    if path.stem in BEFORE_THE_MODEL:
        pytest.skip("refused before a model is chosen (tests/test_study.py covers it)")
    model = SCHEMAS[kind_of_file(path)]
    with pytest.raises(ValidationError):
        model.model_validate(tomllib.loads(path.read_text()))


def test_a_model_appended_to_the_registry_loads_with_the_same_messages(tmp_path):
    # What a new kind does: one model registered; load_model names the key path and value.
    from skidmc.ensemble.study_model import StudyError
    from skidmc.ensemble.study_schema import DistributionSpec, _Table, load_model, register

    @register("toy")
    class ToyFile(_Table):
        MISSING = {"prior": "missing: the prior"}
        prior: DistributionSpec

    try:
        with pytest.raises(StudyError) as info:
            load_model(SCHEMAS["toy"], {"prior": {"distribution": "nrom", "source": "x"}},
                       "toy.toml")
        assert info.value.key == "prior.distribution" and info.value.value == "nrom"
        assert "did you mean 'norm'" in str(info.value)
        with pytest.raises(StudyError, match="^toy.toml: prior: missing: the prior$"):
            load_model(ToyFile, {}, "toy.toml")
    finally:
        del SCHEMAS["toy"]
