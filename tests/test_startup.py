"""What a first height loads: the shortcuts that make ``skidmc height`` start faster leave
every value as it was."""

from __future__ import annotations

import pint
import pytest

from skidmc.scene import materials, presets
from skidmc.scene.units import ureg


def _unit_strings():
    for name, preset in presets.PRESETS.items():
        for key, value in preset["values"].items():
            if isinstance(value, str) and key != "configuration":
                yield f"preset {name} {key}", value
    for name, material in materials.MATERIALS.items():
        for key in ("density", "heat_capacity", "conductivity"):
            value = getattr(material, key, None)
            if isinstance(value, str):
                yield f"material {name} {key}", value


def test_cached_registry_reads_every_shipped_value_as_pint_does():
    # skidmc.scene.units builds its registry from pint's disk cache (cache_folder=":auto:"):
    # every unit string of the presets and materials must convert to the same SI float, bit
    # for bit, as with a registry parsed from pint's definition files.
    plain = pint.UnitRegistry()
    seen = 0
    for what, text in _unit_strings():
        try:
            expected = plain.Quantity(text).to_base_units().magnitude
        except (pint.errors.PintError, ValueError, TypeError, AttributeError, SyntaxError):
            continue  # not a single quantity (a layered target's text, an offset unit)
        assert ureg.Quantity(text).to_base_units().magnitude == expected, what
        seen += 1
    assert seen >= 20  # the presets alone hold more than 20 unit strings


@pytest.mark.parametrize("text", ["28000 psi", "19.1 lb", "530 degR", "0.295 cal/g/K",
                                  "9.2e-4 cal/s/cm/K", "10 in", "60 deg", "50 cal/g"])
def test_cached_registry_converts_the_report_units(text):
    # The report's units, by hand: the same SI value bit for bit with and without the cache.
    assert (ureg.Quantity(text).to_base_units().magnitude
            == pint.UnitRegistry().Quantity(text).to_base_units().magnitude)
