"""The result of a critical-height search.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

__all__ = ["FT", "HeightResult"]

from skidmc.scene.units import FOOT as FT  # [m per ft]


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
