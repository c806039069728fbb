"""docs/inputs.md: its generated tables match the code (scripts/make_inputs_doc.py)."""

from __future__ import annotations

import runpy
from pathlib import Path

from skidmc.scene import INPUT_KEYS, MATERIALS

ROOT = Path(__file__).resolve().parents[1]


def test_inputs_doc_is_up_to_date():
    script = runpy.run_path(str(ROOT / "scripts" / "make_inputs_doc.py"), run_name="check")
    text = (ROOT / "docs" / "inputs.md").read_text(encoding="utf-8")
    assert script["render"](text) == text, "run python scripts/make_inputs_doc.py"
    for k in INPUT_KEYS:
        assert f"| `{k.key}` | " in text
    for m in MATERIALS.values():
        assert f"`{m.name}`" in text and m.source in text


def test_render_rewrites_a_stale_block_and_only_it():
    script = runpy.run_path(str(ROOT / "scripts" / "make_inputs_doc.py"), run_name="check")
    text = (ROOT / "docs" / "inputs.md").read_text(encoding="utf-8")
    stale = text.replace("| `flow_stress` | Pa |", "| `flow_stress` | psi |")
    assert stale != text and script["render"](stale) == text
