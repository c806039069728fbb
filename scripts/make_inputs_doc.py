"""Regenerate the tables of docs/inputs.md from the scene layer's one definition of each input.

The key table comes from :data:`skidmc.scene.keys.INPUT_KEYS`, the materials table from
:data:`skidmc.scene.materials.MATERIALS`; the prose around them is written by hand in
docs/inputs.md. Each generated block sits between ``<!-- BEGIN name -->`` and
``<!-- END name -->`` lines, which this script rewrites and nothing else.

Usage::

    python scripts/make_inputs_doc.py           # rewrite docs/inputs.md
    python scripts/make_inputs_doc.py --check   # exit 1 if docs/inputs.md is out of date

``tests/test_inputs_doc.py`` runs the check.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from skidmc.scene.keys import INPUT_KEYS, SI_UNITS, format_number  # noqa: E402 (after the sys.path set-up)
from skidmc.scene.materials import MATERIALS, TARGET_KEYS  # noqa: E402 (after the sys.path set-up)
from skidmc.scene.units import to_si  # noqa: E402 (after the sys.path set-up)

__all__ = ["BLOCKS", "DOC", "main", "render"]

DOC = ROOT / "docs" / "inputs.md"
_BLOCK = re.compile(r"(<!-- BEGIN (?P<name>[a-z-]+) -->\n)(?:.*?\n)?(<!-- END (?P=name) -->)",
                    re.DOTALL)


def _unit(unit: str) -> str:
    return "-" if unit in ("1", "-") else unit


def _interval(ik) -> str:
    if ik.bounds is None:
        return "`pendulum` or `vertical`"
    b = ik.bounds
    left = "[" if b.low_closed else "("
    right = "]" if b.high_closed else ")"
    high = "inf" if b.high == float("inf") else format_number(b.high)
    return f"{left}{format_number(b.low)}, {high}{right}"


def keys_table() -> str:
    """The table of the 19 scene keys."""
    rows = ["| key | SI unit | allowed | plausible bare number | symbol | meaning "
            "| in the report |",
            "|---|---|---|---|---|---|---|"]
    for ik in INPUT_KEYS:
        plausible = ("-" if ik.plausible is None
                     else f"{format_number(ik.plausible[0])} - {format_number(ik.plausible[1])}")
        rows.append(f"| `{ik.key}` | {_unit(ik.si_unit)} | {_interval(ik)} | {plausible} | "
                    f"{ik.symbol} | {ik.description} | {ik.equation} |")
    return "\n".join(rows)


def materials_table() -> str:
    """The table of the target materials (values in SI) and, below it, their sources."""
    si_units = [SI_UNITS[key] for key in TARGET_KEYS]
    rows = ["| `target =` | " + " | ".join(f"{key.split('.')[1].replace('_', ' ')} [{unit}]"
                                          for key, unit in zip(TARGET_KEYS, si_units))
            + " | diffusivity [mm^2/s] | material |",
            "|---|---|---|---|---|---|---|"]
    for m in MATERIALS.values():
        rho, c, k, p = (to_si(key, m.values[key], unit)
                        for key, unit in zip(TARGET_KEYS, si_units))
        hardness = m.hardness if m.hardness in ("rigid", "elastic") else f"{p:.3g}"
        rows.append(f"| `{m.name}` | {rho:.6g} | {c:.4g} | {k:.4g} | {hardness} | "
                    f"{k / (rho * c) * 1e6:.3g} | {m.description} |")
    rows.append("")
    for m in MATERIALS.values():
        given = ", ".join(m.values.values())
        rows.append(f"- `{m.name}` ({given}): {m.source}. Spread: {m.spread} "
                    f"Hardness: {m.hardness_source}.")
    return "\n".join(rows)


#: Generated blocks of docs/inputs.md: name -> function returning the block's text.
BLOCKS = {"keys": keys_table, "materials": materials_table}


def render(text: str) -> str:
    """`text` (docs/inputs.md) with every generated block rewritten."""
    found = set()

    def block(match: re.Match) -> str:
        found.add(match["name"])
        return match[1] + BLOCKS[match["name"]]() + "\n" + match[3]

    out = _BLOCK.sub(block, text)
    missing = set(BLOCKS) - found
    if missing:
        raise ValueError(f"{DOC}: no generated block for {', '.join(sorted(missing))}")
    return out


def main(argv=None) -> int:
    """Rewrite docs/inputs.md, or with ``--check`` report whether it is up to date."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only check; exit 1 if stale")
    args = parser.parse_args(argv)
    text = DOC.read_text(encoding="utf-8")
    new = render(text)
    if args.check:
        if new != text:
            print(f"{DOC} is out of date: run python scripts/make_inputs_doc.py",
                  file=sys.stderr)
            return 1
        return 0
    if new != text:
        DOC.write_text(new, encoding="utf-8")
        print(f"wrote {DOC}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
