"""The units edge: user values with units in, SI floats out.

Everything inside skidmc works in SI floats (angles in degrees); this module is the only place
where units are interpreted. It holds the package's one :class:`pint.UnitRegistry`, ``ureg``;
no conversion factor is written by hand anywhere in skidmc.

Notes on the report's units, as pint reads them:

- ``cal`` is the thermochemical calorie, 4.184 J exactly, which is the calorie of the report
  (and of most US work of its time). The international-table calorie would be ``cal_it``.
- ``lb`` is the avoirdupois pound *mass*, 0.45359237 kg; the report's billet "weight" W is a mass.
- ``psi`` is pound-force per square inch (6894.757... Pa); ``in``, ``ft`` and ``degR`` (Rankine,
  an absolute scale) are pint's definitions. pint's ``BTU`` is the ISO value 1055.056 J; the
  international-table Btu (1055.05585262 J) is ``Btu_it``.
- Per-degree units (``cal/g/degC``) are temperature *differences* and convert as per kelvin;
  a lone ``degC``/``degF`` (``"20 degC"``) is an absolute temperature (293.15 K).
"""

from __future__ import annotations

import numbers
import re

import pint

from skidmc.errors import SceneError, UnitError
from skidmc.scene.keys import HARDNESS_WORDS, INFINITE_OK

__all__ = ["FOOT", "from_si", "read_si", "to_si", "ureg"]

#: The international foot [m], exact by definition (1959): the one definition in skidmc, for
#: the report's heights in feet. Written as the exact decimal: pint's and scipy.constants' foot
#: (12 x 0.0254) round to 0.30479999999999996.
FOOT = 0.3048



def _registry() -> pint.UnitRegistry:
    """pint's default registry, its parsed definitions kept in pint's disk cache.

    ``cache_folder=":auto:"`` (pint's own cache, in the user's cache folder, invalidated by
    pint when its definition files change) builds the registry in ~15 ms instead of ~0.3 s
    of parsing, a fifth of a ``skidmc height`` call (docs/performance.md). The units are the
    same (``tests/test_units.py`` compares every preset's value with an uncached registry).
    Where the cache cannot be used (no writable cache folder, a file another process is
    writing), the registry is built without it.
    """
    try:
        return pint.UnitRegistry(cache_folder=":auto:")
    except Exception:  # noqa: BLE001 - only a cache: build the registry as pint does without it
        return pint.UnitRegistry()


#: The package's single unit registry. Offset units are *not* auto-converted in products:
#: with ``autoconvert_offset_to_baseunit=True`` pint would read ``cal/g/degC`` as per 274.15 K.
ureg = _registry()

# "<number> <unit expression>" with an optional unit part; the number may be nan/inf so that those
# reach the finiteness check with a clear message rather than failing as a unit.
_NUMBER_THEN_UNIT = re.compile(
    r"""^\s*(?P<number>[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|nan|inf(?:inity)?))
        \s*(?P<unit>.*?)\s*$""",
    re.IGNORECASE | re.VERBOSE,
)


def _root(unit: pint.Unit) -> pint.Unit:
    """Root units of `unit`, keeping dimensionless base units such as the radian apart."""
    return ureg.get_root_units(unit)[1]


def _dimension_label(unit: pint.Unit) -> str:
    """Human-readable dimension of `unit` ("[length]", "angle", "dimensionless")."""
    if _root(unit) == ureg.radian:
        return "angle"
    dim = unit.dimensionality
    return str(dim) if dim else "dimensionless"


def _parse_string(key: str, text: str, expected: pint.Unit) -> tuple[pint.Quantity, bool]:
    """Parse ``"28000 psi"``-style text into a quantity; a bare number is taken in `expected`.
    The flag says whether it was one (no units)."""
    match = _NUMBER_THEN_UNIT.match(text)
    if match is not None:
        magnitude = float(match["number"])
        unit_text = match["unit"]
        if not unit_text:
            return ureg.Quantity(magnitude, expected), True
        try:
            # Quantity(magnitude, unit) rather than parsing the product "20 * degC": the product
            # is ambiguous for offset units and pint refuses it, the constructor is not.
            return ureg.Quantity(magnitude, ureg.parse_units(unit_text)), False
        except (pint.errors.PintError, ValueError, TypeError, AttributeError, SyntaxError):
            pass  # not a plain unit: maybe an expression such as "6.66e5 cal/mol / (296.16 g/mol)"
    try:
        quantity = ureg.parse_expression(text)
    except pint.errors.OffsetUnitCalculusError as exc:
        raise UnitError(
            key, text, f"ambiguous offset unit (write a temperature as e.g. '20 degC'): {exc}"
        ) from None
    except (pint.errors.PintError, ValueError, TypeError, AttributeError, SyntaxError) as exc:
        raise UnitError(key, text, f"cannot parse units ({type(exc).__name__}: {exc})") from None
    if not isinstance(quantity, ureg.Quantity):  # parse_expression returns a number for "2*3"
        return ureg.Quantity(float(quantity), expected), True
    return quantity, False


def to_si(key: str, value: object, expected_unit: str) -> float:
    """Convert one user value to a float in the key's SI unit.

    ``to_si(key, value, unit)`` is ``read_si(key, value, unit)[0]``.

    Parameters
    ----------
    key : str
        Dotted scene key, used only in error messages.
    value : float, int, str or pint.Quantity
        A real number is taken as already in `expected_unit`. A string is either a bare number
        (also taken in `expected_unit`: ``"0.1"``) or a number with units that pint understands
        (``"28000 psi"``, ``"530 degR"``, ``"0.295 cal/g/K"``,
        ``"6.66e5 cal/mol / (296.16 g/mol)"``).
        Temperatures with offset units convert as absolute temperatures (``"20 degC"`` -> 293.15).
    expected_unit : str
        The key's SI unit, as pint spells it (``"Pa"``, ``"J/(kg K)"``, ``"deg"``, ``"1"``).

    Returns
    -------
    float
        The value in `expected_unit`. Non-finite values are returned as such; range checks are
        the caller's (:mod:`skidmc.scene`).

    Raises
    ------
    SceneError
        `value` is a bool, a sequence, ``None`` or another non-scalar.
    UnitError
        The units cannot be parsed, or have the wrong dimension for `key` (an angle unit counts
        as a dimension of its own, so ``"0.1 deg"`` is refused for a dimensionless key).
    """
    return read_si(key, value, expected_unit)[0]


def read_si(key: str, value: object, expected_unit: str) -> tuple[float, bool]:
    """Convert one user value to SI (as :func:`to_si`), and say whether it was a bare number.

    Parameters
    ----------
    key : str
        Dotted scene key, used only in error messages.
    value : float, int, str or pint.Quantity
        As for :func:`to_si`.
    expected_unit : str
        The key's SI unit, as pint spells it.

    Returns
    -------
    value : float
        The value in `expected_unit` [expected_unit].
    bare : bool
        Whether `value` carried no units (a real number, ``"28000"`` or an expression of
        numbers), so that it was read in `expected_unit`: the reading a plausibility check
        (:func:`skidmc.scene.keys.implausible_reason`) is for.

    Raises
    ------
    SceneError, UnitError
        As :func:`to_si`.
    """
    wanted = "a single number" + (f" in [{expected_unit}]" if expected_unit != "1" else "")
    if isinstance(value, bool) or (hasattr(value, "dtype") and value.dtype.kind == "b"):
        raise SceneError(key, value, f"expected {wanted} or a unit string, got a boolean")
    if isinstance(value, numbers.Real):
        # Before any pint call: a plain number needs no units (ensembles build scenes from
        # floats, and parsing the unit cost ~1 ms per scene).
        return float(value), True
    if key in INFINITE_OK and isinstance(value, str) and value.strip().lower() in HARDNESS_WORDS:
        return HARDNESS_WORDS[value.strip().lower()], False  # "rigid" -> inf, "elastic" -> 0
    expected = ureg.parse_units(expected_unit)
    bare = False
    if isinstance(value, pint.Quantity):
        # Re-create in our registry (a quantity from another registry cannot be converted here).
        quantity = ureg.Quantity(float(value.magnitude), str(value.units))
    elif isinstance(value, str):
        quantity, bare = _parse_string(key, value, expected)
    else:
        raise SceneError(
            key, value, f"expected {wanted} or a unit string, got {type(value).__name__}"
        )
    if _root(quantity.units) != _root(expected):
        raise UnitError(
            key, value,
            f"wrong dimension: expected {_dimension_label(expected)} (SI unit {expected_unit}), "
            f"got {_dimension_label(quantity.units)} (unit '{quantity.units:~}')",
        )
    try:
        magnitude = quantity.to(expected).magnitude
    except pint.errors.PintError as exc:  # e.g. an offset unit inside a product
        raise UnitError(key, value, f"cannot convert to {expected_unit}: {exc}") from None
    if not isinstance(magnitude, numbers.Real):
        raise SceneError(key, value, "expected a single number, got an array")
    return float(magnitude), bare




def from_si(value: float, si_unit: str, unit: str) -> float:
    """Convert a float from an SI unit to another unit (for display: metres to feet).

    Parameters
    ----------
    value : float
        Magnitude in `si_unit`.
    si_unit, unit : str
        Units pint understands, of the same dimension.

    Returns
    -------
    float
        `value` expressed in `unit`.
    """
    return float(ureg.Quantity(value, ureg.parse_units(si_unit)).to(unit).magnitude)
