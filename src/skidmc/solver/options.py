"""What one critical-height search is asked, resolved once into a frozen object.

:func:`skidmc.critical_height` takes a dozen keyword arguments whose defaults depend on each
other: the default search (no ``level``, ``model`` or ``extrapolate=False``) is an adaptive
Richardson pair with the exact target and the melting spread of
:data:`skidmc.physics.thermal.MELT_SPREAD`; a forced level keeps one plan, the meshed target
and the fixed melting step. :func:`resolve_options` checks every argument (errors name the
argument and its value) and settles those dependencies in one place; the searches below it
(:mod:`skidmc.solver.search`) read a :class:`SearchOptions` and never a default again.
"""

from __future__ import annotations

import dataclasses
import functools

from skidmc.errors import SceneError
from skidmc.physics.mechanics import (
    EXIT_STOPS_SLIDING,
    contact_pressure,
    impact_constants,
    sliding_velocity,
)
from skidmc.physics.thermal import MELT_SPREAD
from skidmc.solver.model import build_model
from skidmc.solver.plan import (
    first_pair_level,
    melt_width_for_rtol,
    plan_for_rtol,
)

__all__ = ["DEFAULT_H_MAX", "DEFAULT_H_MIN", "FADING_EXIT_SPEED", "METHODS", "TARGETS",
           "SearchOptions", "exit_regime", "margin_likely_jumps", "resolve_options"]

#: How the target is modelled (:func:`skidmc.solver.model.build_model`): "mesh", on its own
#: finite-volume mesh; "exact", the exact semi-infinite solid through Duhamel's integral.
TARGETS = ("mesh", "exact")

#: Default search bounds [m]: 1 mm to 10 km of drop height.
DEFAULT_H_MIN = 1e-3
DEFAULT_H_MAX = 1e4

#: Root finders: Brent's method on the continuous margin, or the report's geometric bisection
#: on go/no-go.
METHODS = ("brent", "bisection")

#: Sliding speed at rebound, as a fraction of the initial one, below which a rebound scene's
#: margin is treated as likely to jump at its root (the heating fades before the exit, so the
#: event comes before the fade or not at all), as where sliding stops: its first root
#: tolerances are split for halvings (:func:`margin_likely_jumps`). On the 16 off-preset
#: scenes of ``skidmc.scene.validation``, the rebound scenes whose margin jumped or folded at the
#: root exit at 0.14-0.47 of the initial speed, the smooth ones at 0.57-0.90 (the presets
#: 0.81-0.92). At rtol 1e-3 the four below 0.5 took 1-2 fewer simulations (11-12 against
#: 12-14); on a fresh draw (seed 17) the one rebound scene below 0.5 took 11 against 14, and
#: one at 0.59 still jumped (13 either way): the threshold misses some, never costs.
FADING_EXIT_SPEED = 0.5


def exit_regime(scene):
    """How the scene's heating ends: "stops_sliding" (before rebound), "fading" (a rebound with
    the sliding speed at rebound, report Eq. 10, below :data:`FADING_EXIT_SPEED` of the initial
    one) or "steady" (the other rebounds)."""
    pressure = contact_pressure(scene.flow_stress, scene.target_hardness)
    _, _, t_exit, exit_code, _, _ = impact_constants(
        scene.mu, pressure, scene.billet_mass, scene.billet_diameter, scene.angle, scene.tilt)
    if exit_code == EXIT_STOPS_SLIDING:
        return "stops_sliding"
    speed_at = functools.partial(sliding_velocity, height=1.0, mu=scene.mu, angle=scene.angle,
                                 tilt=scene.tilt, flow_stress=pressure,
                                 billet_mass=scene.billet_mass,
                                 billet_diameter=scene.billet_diameter)
    return "fading" if speed_at(t_exit) < FADING_EXIT_SPEED * speed_at(0.0) else "steady"


def margin_likely_jumps(scene):
    """Whether the scene's margin is likely to jump at its root [bool]: sliding stops before
    rebound, or the heating fades before rebound (:func:`exit_regime`).

    Only the first root tolerances depend on it
    (:func:`skidmc.solver.controller.first_root_tolerances`); every estimate uses the
    tolerances actually used.
    """
    return exit_regime(scene) != "steady"


@dataclasses.dataclass(frozen=True)
class SearchOptions:
    """The resolved options of one full-tier critical-height search (frozen).

    :func:`resolve_options` makes the one :func:`skidmc.critical_height` searches with; the
    defaults here are those of a plain search at one level (meshed target, fixed melting step),
    what tests and benchmarks of a single search take.

    Attributes
    ----------
    rtol : float
        Relative tolerance on the critical height [1].
    h_min, h_max : float
        Search bounds [m].
    method : {"brent", "bisection"}
        Root finder.
    melting : bool
        Model melting of the HE.
    runaway_fraction : float or None
        The runaway rule's fraction [1], or None for the kernel's default
        (:data:`skidmc.physics.thermal.DEFAULT_RUNAWAY_FRACTION`).
    melt_width : float
        Width of the smoothed melting step [K]; the same at every level of the search.
    melt_spread : float
        Spread of each HE cell's melting step over its temperature range [1].
    target : {"exact", "mesh"}
        How the target is modelled.
    level : float
        The forced or planned level; the first pair's fine level of the adaptive search.
    extrapolate : bool
        Richardson extrapolation from ``level - 1`` and ``level``.
    adaptive : bool
        The default search: pairs refined until their own estimate meets rtol.
    signs : bool
        The scene's margin is likely to jump at its root (:func:`margin_likely_jumps`; only
        the adaptive search uses it).
    regime : str or None
        How the scene's heating ends (:func:`exit_regime`), found once for the search; None
        where no scene was resolved (a given model, or options made by hand: the search
        finds it).
    """

    rtol: float
    melt_width: float
    h_min: float = DEFAULT_H_MIN
    h_max: float = DEFAULT_H_MAX
    method: str = "brent"
    melting: bool = True
    runaway_fraction: float | None = None
    melt_spread: float = 0.0
    target: str = "mesh"
    level: float = 0.0
    extrapolate: bool = False
    adaptive: bool = False
    signs: bool = False
    regime: str | None = None

    @property
    def exact(self):
        """Whether the target is the exact semi-infinite solid [bool]."""
        return self.target == "exact"

    def model_kwargs(self):
        """The runaway rule as :func:`skidmc.solver.model.build_model` takes it [dict]."""
        return {} if self.runaway_fraction is None else {"runaway_fraction":
                                                          self.runaway_fraction}

    def with_melt_width(self, melt_width):
        """These options with another melting width [K] (a new object)."""
        return dataclasses.replace(self, melt_width=float(melt_width))


def resolve_options(scene, rtol, *, h_min, h_max, method="brent", level=None, extrapolate=None,
                    melting=True, runaway_fraction=None, model=None, melt_width=None,
                    melt_spread=None, target=None, terms_of=None):
    """Check a full-tier search's arguments and resolve their defaults [SearchOptions].

    See :func:`skidmc.critical_height` for the arguments (``h_min`` < ``h_max`` are checked
    there). Raises :class:`skidmc.errors.SceneError` naming the argument and its value.
    ``terms_of``: a function of no argument giving the scene's model terms at ``rtol`` with
    the default runaway rule, where the caller has them (a
    :class:`skidmc.solver.model.ModelBuilder`'s); by default a mesh-less model is built for
    them.
    """
    if not (isinstance(rtol, (int, float)) and 0.0 < rtol < 0.5):
        raise SceneError("rtol", rtol, "must be a number in (0, 0.5)")
    if method not in METHODS:
        raise SceneError("method", method, "expected 'brent' or 'bisection'")
    if melt_width is not None and not (isinstance(melt_width, (int, float))
                                       and melt_width > 0.0):
        raise SceneError("melt_width", melt_width, "must be a number > 0 [K]")
    if melt_spread is not None and not (isinstance(melt_spread, (int, float))
                                        and 0.0 <= melt_spread <= 1.5):
        # Beyond ~1.5 the first HE cell's Newton iterations stopped converging (2.0 failed on
        # paper-gold).
        raise SceneError("melt_spread", melt_spread, "must be a number in [0, 1.5]")
    # The default: Richardson pairs refined until their own (a posteriori) error estimate meets
    # rtol, the calibrated model choosing only the first pair. A forced level, a given model or
    # extrapolate=False keep one plan, with the calibrated model's estimate.
    adaptive = level is None and model is None and extrapolate is not False
    if melt_spread is None:
        melt_spread = MELT_SPREAD if adaptive else 0.0
    if target is None:
        # The exact target is homogeneous with constant properties: a stack whose heat
        # reaches below its top layer, or a target whose properties follow its temperature, is
        # meshed (docs/targets.md).
        terms = (build_model(scene, meshes=False, rtol=rtol).terms if terms_of is None
                 else terms_of())
        layered = "layered_target" in terms or "temperature_target" in terms
        target = "exact" if adaptive and not layered else "mesh"
    elif target not in TARGETS:
        raise SceneError("target", target, f"expected one of {', '.join(TARGETS)}")
    # How the heating ends, once (margin_likely_jumps: any regime but "steady").
    regime = exit_regime(scene) if model is None else None
    signs = adaptive and regime != "steady"
    if adaptive:
        level, extrapolate = first_pair_level(rtol, target == "exact", signs), True
    elif level is None:
        level, planned = plan_for_rtol(rtol)
        extrapolate = planned if extrapolate is None else extrapolate
    extrapolate = bool(extrapolate) and model is None and level >= 1.0
    if melt_width is None:
        # The same width at every level of the search (coarse start, Richardson pairs).
        melt_width = melt_width_for_rtol(rtol, level)
    return SearchOptions(rtol=rtol, h_min=h_min, h_max=h_max, method=method, melting=melting,
                         runaway_fraction=runaway_fraction, melt_width=float(melt_width),
                         melt_spread=float(melt_spread), target=target, level=level,
                         extrapolate=extrapolate, adaptive=adaptive, signs=signs,
                         regime=regime)
