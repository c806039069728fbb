"""The result of a critical-height search.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

__all__ = ["FT", "IMPLAUSIBLE_INPUT", "RESULT_FLAG_MEANINGS", "RTOL_UNMET", "HeightResult",
           "flag_unmet_rtol"]

from skidmc.scene.units import FOOT as FT  # [m per ft]

#: The flag of a result whose error estimate stayed above the requested ``rtol``: the search
#: refined as far as it goes (:data:`skidmc.solver.plan.MAX_ADAPTIVE_LEVEL`, the melting
#: width's floor) and stopped; ``error_estimate`` is what it reached.
RTOL_UNMET = "rtol_unmet"

#: The flag of an ensemble sample with an input outside its key's plausible range
#: (:func:`skidmc.scene.scenes.implausible_inputs`): computed as given, but the model was not
#: made for it and its height may mean nothing.
IMPLAUSIBLE_INPUT = "implausible_input"

#: Meanings of the flags a result or a sample carries besides the model's validity flags
#: (:data:`skidmc.solver.model.FLAG_MEANINGS`).
RESULT_FLAG_MEANINGS: dict[str, str] = {
    RTOL_UNMET: "the requested rtol was not reached (the search refined as far as it goes); "
                "the error estimate is what was reached",
    IMPLAUSIBLE_INPUT: "an input lies outside its key's plausible range: the model was not "
                       "made for it and the height may mean nothing",
}

#: Relative slack on ``error_estimate <= rtol`` before a result is flagged :data:`RTOL_UNMET`
#: [1]: the adaptive search stops once its estimate is within ``rtol (1 + 1e-12)``; 1e-9 keeps
#: rounding of the estimate's sum from flagging a met tolerance.
RTOL_SLACK = 1e-9


@dataclass
class HeightResult:
    """Critical drop height of one scene.

    Attributes
    ----------
    critical_height : float
        Critical drop height [m]; for censored results the bound that was hit.
    censored : str or None
        None, ``"above"`` (no event up to ``h_max``) or ``"below"`` (event at ``h_min``).
    evaluations : int
        Number of impact simulations used.
    flags : tuple of str
        Model-validity notes, e.g. ``"stops_sliding"`` (heating ended before rebound),
        ``"no_friction"``.
    error_estimate : float
        Estimated relative numerical error of ``critical_height`` [1].
    extrapolated : bool
        The height is the Richardson extrapolation of two levels.
    richardson_correction : float
        Relative size of that extrapolation's correction [1]: an a-posteriori error
        indicator of the finer level alone (0 when not extrapolated).
    melt_bias_estimate : float
        The part of ``error_estimate`` that bounds the smoothed melting step's bias [1]: the
        calibrated bound, or the bias measured on this scene when larger (default search).
    rtol, level, method, wall_time, exit_time, exit_kind, terms
        Settings and diagnostics (wall_time [s], exit_time [s]).
    """

    critical_height: float
    censored: str | None
    evaluations: int
    flags: tuple = ()
    error_estimate: float = math.nan
    rtol: float = 1e-3
    level: float = 0.0
    method: str = "brent"
    wall_time: float = 0.0
    exit_time: float = math.nan
    exit_kind: str = ""
    terms: tuple = ()
    extrapolated: bool = False
    richardson_correction: float = 0.0
    melt_bias_estimate: float = 0.0
    history: list = field(default_factory=list, repr=False)

    @property
    def critical_height_ft(self):
        """Critical drop height [ft]."""
        return self.critical_height / FT

    def to_dict(self):
        """JSON-ready dictionary (heights in m and ft)."""
        d = asdict(self)
        d.pop("history")
        d["critical_height_m"] = d.pop("critical_height")
        d["critical_height_ft"] = self.critical_height_ft
        d["flags"] = list(self.flags)
        d["terms"] = list(self.terms)
        return d

    @property
    def rtol_unmet(self) -> bool:
        """Whether the requested ``rtol`` was not reached (flag :data:`RTOL_UNMET`);
        ``error_estimate`` is then the relative error reached [1]."""
        return RTOL_UNMET in self.flags


def flag_unmet_rtol(result, rtol):
    """`result` with :data:`RTOL_UNMET` added to its flags where its ``error_estimate`` stayed
    above the requested `rtol` [1] (uncensored results of the full tier; idempotent).

    Works on any object with ``flags``, ``censored`` and ``error_estimate`` (a stand-in solver's
    result too); a :class:`HeightResult` is returned as a new object, others are changed in place
    where they allow it. Returns `result` unchanged when nothing is to flag.
    """
    import dataclasses

    error = getattr(result, "error_estimate", math.nan)
    flags = tuple(getattr(result, "flags", ()) or ())
    if (getattr(result, "censored", None) is not None or RTOL_UNMET in flags
            or not isinstance(error, (int, float)) or not math.isfinite(error)
            or not isinstance(rtol, (int, float)) or not error > rtol * (1.0 + RTOL_SLACK)):
        return result
    if dataclasses.is_dataclass(result) and not isinstance(result, type):
        return dataclasses.replace(result, flags=(*flags, RTOL_UNMET))
    try:
        result.flags = (*flags, RTOL_UNMET)
    except AttributeError:
        pass
    return result
