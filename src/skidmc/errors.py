"""Exceptions raised by skidmc.

Every problem with a user's input is a :class:`SceneError` (also a :class:`ValueError`) that names
the offending key and value, so a message read on its own says what to fix::

    flow_stress = '-5 psi': must be > 0
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable

__all__ = ["MissingKeyError", "SceneError", "SkidmcError", "UnitError", "UnknownKeyError"]


class SkidmcError(Exception):
    """Base class of all errors raised on purpose by skidmc."""


class SceneError(SkidmcError, ValueError):
    """An input value is unusable: wrong type, out of range, inconsistent with another input.

    Parameters
    ----------
    key : str
        Dotted scene key (``"he.density"``), or the name of the option that was wrong.
    value : object
        The value as the user gave it (a unit string stays a string).
    reason : str
        What is wrong with it, phrased as the rule it breaks ("must be > 0").

    Attributes
    ----------
    key, value, reason
        As given; ``str(err)`` is ``"{key} = {value!r}: {reason}"``.
    """

    def __init__(self, key: str, value: object, reason: str) -> None:
        self.key = key
        self.value = value
        self.reason = reason
        super().__init__(f"{key} = {value!r}: {reason}")

    def __reduce__(self):
        # Keep the three-argument constructor picklable (errors cross process boundaries).
        return (type(self), (self.key, self.value, self.reason))


class UnknownKeyError(SceneError):
    """A key that is not in the scene vocabulary; the message suggests the closest valid keys.

    Parameters
    ----------
    key : str
        The unknown key.
    value : object
        The value given for it.
    valid : iterable of str, optional
        The valid keys, used to suggest close matches (:func:`difflib.get_close_matches`).
    reason : str, optional
        Full reason text; built from `valid` when not given.
    """

    def __init__(
        self, key: str, value: object, valid: Iterable[str] = (), reason: str | None = None
    ) -> None:
        if reason is None:
            valid = list(valid)
            close = difflib.get_close_matches(key, valid, n=3, cutoff=0.6)
            if close:
                hint = "did you mean " + " or ".join(repr(c) for c in close) + "?"
            else:
                hint = "valid keys: " + ", ".join(valid)
            reason = f"unknown key; {hint}"
        super().__init__(key, value, reason)

    def __reduce__(self):
        return (type(self), (self.key, self.value, (), self.reason))


class MissingKeyError(SceneError):
    """A required key was given no value (no preset to take it from).

    ``value`` is ``None``; the message lists every missing key, ``key`` is the first of them.
    """

    def __init__(self, key: str, value: object = None, reason: str = "missing") -> None:
        super().__init__(key, value, reason)

    def __str__(self) -> str:
        return f"{self.key}: {self.reason}"


class UnitError(SceneError):
    """A unit string that pint cannot parse, or a quantity of the wrong dimension for its key."""
