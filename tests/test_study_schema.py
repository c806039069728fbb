"""The declared schemas of the study formats (skidmc.ensemble.study_schema): exported per kind
into docs/schemas, kept current, and in step with the loaders on the shipped studies and on the
structural mistakes of the malformed corpus."""

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


@pytest.mark.parametrize("name, where", [
    ("missing_source", "source"), ("missing_seed", "seed"), ("missing_design", "design"),
    ("hazard_drop_height_without_source", "source"), ("relative_not_bool", "relative"),
    ("hazard_unknown_material", None)])
def test_structural_mistakes_fail_the_schema_too(name, where):
    path = ROOT / "tests" / "malformed_studies" / f"{name}.toml"
    model = SCHEMAS[kind_of_file(path)]
    doc = tomllib.loads(path.read_text())
    if where is None:  # a mistake of meaning, not of structure: only the loader finds it
        model.model_validate(doc)
        return
    with pytest.raises(ValidationError, match=where):
        model.model_validate(doc)
