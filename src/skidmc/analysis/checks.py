"""Argument checks shared by the analysis modules (gonogo, rare_events, hazard, sensitivity,
posterior, planning).

Every bad argument of the analysis layer raises a :class:`ValueError` whose message names the
argument and shows its value, ``"{name} = {value!r}: {reason}"``, so a user sees at once what to
change. The checks return the value in the type the caller computes with.
"""

from __future__ import annotations

import math
import numbers

__all__ = [
    "bad",
    "check_confidence",
    "check_positive_float",
    "check_positive_int",
    "check_probability",
    "check_seed",
]


def bad(name: str, value: object, reason: str) -> ValueError:
    """A ValueError in skidmc's style: ``"{name} = {value!r}: {reason}"``.

    A repr longer than 300 characters (a long array) is cut, so that it does not bury the reason.
    """
    text = repr(value)
    if len(text) > 300:
        text = text[:300] + "..."
    return ValueError(f"{name} = {text}: {reason}")


def _is_real(value: object) -> bool:
    return not isinstance(value, bool) and isinstance(value, numbers.Real)


def check_seed(seed: object) -> int:
    """An integer seed >= 0 (0 is a seed like any other; None is refused: results must repeat)."""
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise bad("seed", seed, "expected an integer >= 0 (0 is a seed like any other)")
    return int(seed)


def check_positive_int(name: str, value: object, minimum: int = 1) -> int:
    """An integer >= `minimum` (booleans refused)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise bad(name, value, f"expected an integer >= {minimum}")
    return int(value)


def check_positive_float(name: str, value: object) -> float:
    """A finite real number > 0 (booleans refused)."""
    if not _is_real(value) or not (math.isfinite(value) and value > 0):  # type: ignore[arg-type]
        raise bad(name, value, "expected a finite number > 0")
    return float(value)  # type: ignore[arg-type]


def check_probability(name: str, value: object) -> float:
    """A real number strictly between 0 and 1 (booleans refused)."""
    if not _is_real(value) or not 0.0 < value < 1.0:  # type: ignore[operator]
        raise bad(name, value, "expected a number in (0, 1)")
    return float(value)  # type: ignore[arg-type]


def check_confidence(confidence: object) -> float:
    """A confidence level in (0, 1), e.g. 0.95."""
    return check_probability("confidence", confidence)
