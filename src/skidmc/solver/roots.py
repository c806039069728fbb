"""Root finders of the search, each a pure function of a margin m(x), x = ln H.

``margin(x)`` runs (or recalls) one simulation and returns ln(t_ev / t_exit): go <=> m <= 0.
The finders differ in what they know beforehand: a guess and a slope (:func:`go_side_root`,
:func:`guided_root`), a guess and its scatter (:func:`prior_bisection_root`), nothing
(:func:`brent_root`, :func:`bisection_root`).
"""

from __future__ import annotations

import math
from statistics import NormalDist

from skidmc.solver.simulate import SolverError

__all__ = [
    "CARRIED_GO_SLOPE_ERROR",
    "DEFAULT_GO_SLOPE",
    "DEFAULT_GO_SLOPE_ERROR",
    "FAST_GUESS_ERROR",
    "FOLD_SLOPE",
    "GO_BEND",
    "GO_MIN_SEPARATION",
    "GO_SECANT_SPAN",
    "JUMP_SLOPE",
    "PRIOR_TAIL",
    "PRIOR_TAIL_Z",
    "bisection_root",
    "brent_root",
    "go_side_root",
    "go_side_slope",
    "guided_root",
    "margin_slope",
    "prior_bisection_root",
]

_EPS = 2.220446049250313e-16  # float64 machine epsilon, np.finfo(float).eps

#: Relative error of the fast tier's height used as a first guess [1]: about its median
#: against the full model on the studies' ranges (1.3 %; p90 4.6 %, worst ~10 %,
#: results/benchmarks/fast_tier.md). The go-side search starts this far above the guess;
#: a guess further off costs one or two more simulations, never a wrong root.
FAST_GUESS_ERROR = 0.02

#: d margin / d ln H on the go side [1] when nothing better is known: t_ev ~ H^-s with s
#: measured 1.1-1.35 on the report presets (rebound exits), and its relative uncertainty.
DEFAULT_GO_SLOPE = -1.25
DEFAULT_GO_SLOPE_ERROR = 0.3
#: Relative uncertainty of a go-side slope carried over from a coarser level's search.
#: Measured against the fine level's own secant from the root to 0.2-2 % above it, on the
#: report presets (gold aside: stops sliding) for the Richardson pairs (0, 1) and (0.5, 1.5):
#: 0.05 % to 9.6 % (alumina 50-80 uin, pair (0.5, 1.5)); 0.15 leaves 1.5x to spare. It
#: bounds the error of a root extrapolated from one fine go point (:func:`go_side_root`).
CARRIED_GO_SLOPE_ERROR = 0.15
#: Go points farther than this from the root [1, in ln H] are not used for the secant slope.
GO_SECANT_SPAN = 0.1
#: Closest spacing [1, in ln H] of the two go points of a secant: the margin's ~1e-5 step-size
#: noise then moves the secant's slope by ~1 % at most.
GO_MIN_SEPARATION = 2e-3
#: Bend of the go-side margin [1]: a secant through go points at distances d_a < d_b (in
#: ln H) from the root misses it by about GO_BEND * d_a * d_b (a quadratic's interpolation
#: error, kappa d_a d_b / (2 |s|)). ``python scripts/go_side_bend.py``
#: (results/validation/go_side_bend.md) measures kappa = |miss| / (d_a d_b) on the presets and
#: the off-preset scenes with a smooth go side, at the levels and widths of the default pairs:
#: at most 9.6 from level 0.5 up (0.1-2 on most scenes; 3.7-7.6 on a pendulum whose go side
#: is twice as steep as the presets'; 8-9.6 from the margin's ~1e-4 jitter at level 1 with a
#: 3 K step, over the closest pairs). The first pass assumed 1.0 from one preset (0.39), and a
#: secant accepted by it missed its root by up to 1.7 x_tol. Level 0's margin jumps by up to
#: ~1.5e-3 between heights 0.1 % apart (kappa up to ~340 there): its discretisation, which the
#: Richardson estimate of a pair (0, 1) covers, not a bend any secant could model.
GO_BEND = 10.0
#: Steepest secant [1, d margin / d ln H] across a bracket of a margin that is smooth through
#: its root: t_ev ~ H^-s gives |slope| 1.1-1.35 on the go side, ~30 % less on the no-go side.
#: A jump (the event before the heating fades, or never) gives 0.3-0.5 of margin over a
#: bracket of ~1e-3 or less, hundreds; 10 separates the two at every bracket the searches use
#: (at most ~0.03 wide: a 0.3 jump is then still steeper).
JUMP_SLOPE = 10.0
#: Steepest go-side secant [1] along which :func:`go_side_root` extrapolates to the root: about
#: twice the measured 1.1-1.35. A steeper go side is approaching a fold (the event time's
#: square-root approach to where the event ceases; off-preset vertical drops, slopes ~16 within
#: 0.3 % of H_c): it bends far more than :data:`GO_BEND`, and the root is bracketed instead.
FOLD_SLOPE = 3.0


def margin_slope(history):
    """d margin / d ln H [1] across the sign change of a finished search's history, or None.

    -inf where the no-go end has no event (margin inf: a run stopped at the exit, searched by
    its signs, or none within the horizon): the margin is taken to jump there (steeper than
    :data:`JUMP_SLOPE`), so the next search locates the root by its signs too.
    """
    pts = [(math.log(h), m) for h, m in history if not math.isnan(m)]
    for (x0, m0), (x1, m1) in zip(pts, pts[1:]):
        if m0 > 0.0 >= m1 and x1 > x0:
            return -math.inf if m0 == math.inf else (m1 - m0) / (x1 - x0)
    return None


def _margin_inside(margin, x, x_min, x_max, no_event_ok=False):
    """The margin at ``x``, or None when x leaves (x_min, x_max) or the margin is not finite
    (with ``no_event_ok``, inf, "no event", is kept: a search by signs): the guided searches
    then hand over to bracketing and Brent's method."""
    if not (x_min < x < x_max):
        return None
    m = margin(x)
    return m if math.isfinite(m) or (no_event_ok and m == math.inf) else None


def go_side_slope(history):
    """d margin / d ln H [1] between the two go points (m <= 0) closest to the root, or None."""
    go = [(math.log(h), m) for h, m in history if math.isfinite(m) and m <= 0.0]
    if len(go) < 2:
        return None
    (x0, m0), (x1, m1) = go[0], go[1]
    slope = (m1 - m0) / (x1 - x0)
    return slope if slope < 0.0 else None


def go_side_root(margin, x_guess, slope, x_tol, x_min, x_max, *, guess_error,
                  max_simulations=8, points=()):
    """Root of the margin on ln H by extrapolation from its go side (m <= 0); or None.

    For a rebound exit the margin is analytic on the go side up to the root: the event
    comes before t_exit, under the true flux, and t_ev ~ H^-s with s nearly constant (its
    secant slope changes by < 1 % over 5 % of H on the report presets). On the no-go side
    the event falls after t_exit, under the extension flux, and the margin bends (its slope
    changes by ~30 % within 0.5 % of H_c, with a kink at the root). So the root is taken from
    a secant through go points only, once the closest go point lies within ``4 x_tol`` of
    it (the extrapolation error is then that distance times the slope's relative change over
    it, far below ``x_tol``) or the secant's modelled bend error (:data:`GO_BEND`) is below
    ``x_tol / 2``. With one go point and a slope carried from a coarser level, the root is
    extrapolated along that slope and accepted when its modelled error, the distance times
    :data:`CARRIED_GO_SLOPE_ERROR`, is below ``x_tol / 2``. The secant uses the farthest go point
    within :data:`GO_SECANT_SPAN`, which keeps the margin's ~1e-5 step-size noise out of the slope.

    Each simulation aims just above the predicted root, by the prediction's own uncertainty
    (at least ``1.5 x_tol``), so that it lands on the go side: from a coarse level's root and
    slope this usually takes 2 simulations, from the fast tier's height 3. A no-go point
    only bounds the root from below (and closes a bracket, accepted by linear interpolation
    when it is ``4 x_tol`` wide). Returns None when the steps leave [x_min, x_max], meet a
    non-finite margin, contradict monotonicity or do not converge: the caller then brackets
    and runs Brent's method, reusing every simulation. ``points``: (x, m) already known (the
    same search at a looser tolerance), used with the new ones.
    """
    known = slope is not None and slope < 0.0
    slope = slope if known else DEFAULT_GO_SLOPE
    slope_error = CARRIED_GO_SLOPE_ERROR if known else DEFAULT_GO_SLOPE_ERROR
    push = 1.5 * x_tol
    go = sorted((x, m) for x, m in points if m <= 0.0)  # closest to the root first
    no_go = [(x, m) for x, m in points if m > 0.0]
    lo = max(no_go) if no_go else None  # (x, m) of the highest no-go point (m > 0)
    x = x_guess + guess_error
    for _ in range(max_simulations):
        m = _margin_inside(margin, x, x_min, x_max)
        if m is None:
            return None
        if m > 0.0:
            if lo is None or x > lo[0]:
                lo = (x, m)
        else:
            go.append((x, m))
            go.sort()
        if go and lo is not None and lo[0] >= go[0][0]:
            return None  # not monotone at this scale: leave it to Brent
        if go and lo is not None and not _is_smooth(lo, go[0]):
            # The margin jumps (or is too steep to interpolate) at the root: no extrapolation
            # holds; halve the bracket.
            return guided_root(margin, 0.5 * (lo[0] + go[0][0]), None, x_tol, x_min, x_max,
                               points=[lo, go[0]])
        if go:
            xa, ma = go[0]
            far = [p for p in go[1:] if p[0] - xa <= GO_SECANT_SPAN]
            if far:
                # The closest go point at least GO_MIN_SEPARATION beyond xa (the smallest bend
                # error d_a d_b with the noise kept out of the slope), else the farthest.
                spaced = [p for p in far if p[0] - xa >= GO_MIN_SEPARATION]
                xb, mb = spaced[0] if spaced else far[-1]
                secant = (mb - ma) / (xb - xa)
                if not secant < 0.0:
                    return None
                root = xa - ma / secant
                if secant < -FOLD_SLOPE:
                    # Near a fold: the go side bends far more than GO_BEND allows; bracket.
                    return guided_root(margin, root, None, x_tol, x_min, x_max,
                                       spread=max(push, xa - root),
                                       points=go + ([lo] if lo is not None else []))
                bend = GO_BEND * (xa - root) * (xb - root)
                if (xa - root <= 4.0 * x_tol or bend <= 0.5 * x_tol) and (
                        lo is None or root >= lo[0]):
                    return root
                uncertainty = max(push, bend)
            else:
                root = xa - ma / slope
                # Extrapolating with a slope known to slope_error misses the root by
                # about slope_error (xa - root): one go point suffices when that is small.
                extrapolation_error = slope_error * (xa - root)
                if known and slope >= -FOLD_SLOPE and extrapolation_error <= 0.5 * x_tol and (
                        lo is None or root >= lo[0]):
                    return root
                uncertainty = max(push, extrapolation_error)
            if lo is not None:
                if xa - lo[0] <= 4.0 * x_tol:
                    return lo[0] + lo[1] * (xa - lo[0]) / (lo[1] - ma)
                if root <= lo[0]:
                    # The go-side prediction is contradicted by a no-go point: interpolate
                    # in the bracket instead.
                    root = lo[0] + lo[1] * (xa - lo[0]) / (lo[1] - ma)
                    uncertainty = push
            x = root + uncertainty
            if x >= xa - 0.5 * push:
                # The prediction gives no progress: halve the way to the bracket's low end
                # (or to the root predicted from below).
                x = 0.5 * (xa + (lo[0] if lo is not None else root - uncertainty))
        else:
            # Only no-go points: t_ev ~ H^-s predicts the root above; aim past it.
            root = lo[0] - lo[1] / slope
            x = root + max(push, slope_error * (root - lo[0]))
    return None


def _is_smooth(lo, hi):
    """Whether the bracket ``lo`` = (x, m > 0), ``hi`` = (x, m <= 0) may be interpolated [bool].

    Its secant is no steeper than :data:`FOLD_SLOPE` (the smooth margin's |slope| is 1.1-1.35
    on the go side, ~30 % less on the no-go side). A steeper bracket holds a jump (the event
    either comes before the heating fades or not at all: secants of hundreds across brackets
    of ~1e-3, :data:`JUMP_SLOPE`) or the fold's steep approach, where linear interpolation inside a
    4 x_tol bracket missed the root by 1.3 x_tol (alumina-vertical-5 at level 0, secant slope
    8): it is halved to 2 x_tol instead.
    """
    return (lo[1] - hi[1]) <= FOLD_SLOPE * (hi[0] - lo[0])


def _closer_bracket(lo, hi, x, m):
    """``(lo, hi)`` after the point (x, m): the highest no-go point (m > 0) and the lowest go
    point (m <= 0) seen, each (x, m) or None."""
    if m > 0.0 and (lo is None or x > lo[0]):
        return (x, m), hi
    if m <= 0.0 and (hi is None or x < hi[0]):
        return lo, (x, m)
    return lo, hi


def guided_root(margin, x0, slope, x_tol, x_min, x_max, max_simulations=40, *, spread=None,
                points=()):
    """Root of the margin on ln H from a close guess ``x0``, always from a tight bracket; or None.

    The margin is smooth but not linear near the root (its slope changes by ~30 % within
    0.5 % of H_c, and it has a kink at the root itself, where the event moves from before to
    after the exit) and carries ~1e-4 of step-size noise, so a root extrapolated from one
    side is not trusted. Steps aim past the predicted root by ``1.5 x_tol`` so that they
    bracket it; once a bracket [a, b] with m(a) > 0 >= m(b) is at most 4 x_tol wide, the
    root is the linear interpolation inside it (error below the bracket width times the
    slope's relative change, < x_tol). The first step uses ``slope`` (d margin / d ln H from
    a coarser search; -1, the t_ev ~ 1/H scaling, when not known or infinite).

    Where the margin jumps at the root (not :func:`_is_smooth`: sliding stops before rebound, or a
    heating pulse that fades before the exit, so that the event comes before the fade or never)
    its values say nothing about where in the bracket the root lies: the bracket is halved
    until it is at most ``2 x_tol`` wide and its midpoint returned (error <= x_tol). One-sided
    steps are then limited to ``spread`` [1, in ln H] (doubled after each), the uncertainty of
    the guess, instead of following the margin's slope across the jump. ``points``: (x, m)
    already known (e.g. a bracket found by :func:`go_side_root`).

    Returns None when the steps leave [x_min, x_max], meet a non-finite margin, or do not
    converge: the caller then brackets and runs Brent's method, reusing every simulation.
    """
    slope = slope if slope is not None and -math.inf < slope < 0.0 else -1.0
    push = 1.5 * x_tol
    step = spread
    lo = hi = None  # (x, m) of the closest no-go (m > 0) and go (m <= 0) points

    def record(x, m):
        nonlocal lo, hi
        lo, hi = _closer_bracket(lo, hi, x, m)

    for x, m in points:
        record(x, m)
    previous = None
    x = x0
    for _ in range(max_simulations + 1):
        if lo is not None and hi is not None:
            if lo[0] >= hi[0]:
                return None  # not monotone at this scale: leave it to Brent
            if not _is_smooth(lo, hi):
                if hi[0] - lo[0] <= 2.0 * x_tol:
                    return 0.5 * (lo[0] + hi[0])
                x = 0.5 * (lo[0] + hi[0])
            else:
                root = lo[0] + lo[1] * (hi[0] - lo[0]) / (lo[1] - hi[1])
                if hi[0] - lo[0] <= 4.0 * x_tol:
                    return root
                # Shrink from the far end: step past the interpolated root, away from the
                # nearer end, so that the new point lands on the far side's sign.
                x = root - push if root - lo[0] > hi[0] - root else root + push
        elif previous is not None:
            # One-sided: the given slope's (or the secant's) prediction, pushed past the root.
            xp, mp = previous
            delta = -mp / slope + (push if mp > 0.0 else -push)
            if step is not None:
                delta = max(-step, min(step, delta))
                step *= 2.0
            x = xp + delta
        m = _margin_inside(margin, x, x_min, x_max)
        if m is None:
            return None
        if (lo is None or hi is None) and previous is not None and x != previous[0]:
            secant_slope = (m - previous[1]) / (x - previous[0])
            if secant_slope < 0.0:
                slope = secant_slope
        record(x, m)
        previous = (x, m)
    return None


#: Prior probability inside a bracket below which :func:`prior_bisection_root` stops placing
#: its points by the prior (the guess was off by more than its scatter) and bisects in ln H.
PRIOR_TAIL = 0.01
#: One-sided, beyond this many sigma from the guess :func:`prior_bisection_root` steps out in
#: doubling multiples of its distance instead of halving the prior's tail.
PRIOR_TAIL_Z = 1.5

_STANDARD_NORMAL = NormalDist()


def prior_bisection_root(margin, x_guess, sigma, x_tol, x_min, x_max, max_simulations=40, *,
                         slope=None, points=(), signs_only=False):
    """Root of a margin that may jump at its root, from a guess with a known spread; or None.

    Where sliding stops before rebound the margin jumps at the root (not :func:`_is_smooth`): its
    values say nothing about where the root lies, only their signs do. With the root's prior
    ln H ~ N(``x_guess``, ``sigma``^2) (the guess's measured scatter), each simulation is placed
    at the prior's median inside the current bracket (one end may still be missing), which
    halves the prior probability left. A bracket holding less than :data:`PRIOR_TAIL` of it, or
    one known beforehand (a re-search at a tighter tolerance) is bisected in ln H; a missing end
    beyond :data:`PRIOR_TAIL_Z` sigma (the guess off by more than its scatter) is sought in
    steps that double the distance from the guess. From a
    fast-tier guess with sigma = 2 % a bracket of 2 ``x_tol`` = 6e-4 takes ~7 simulations,
    against ~10 for stepping out along the margin's slope and then bisecting. A jump bracket
    is accepted when at most ``2 x_tol`` wide (its midpoint, error <= x_tol); a bracket
    across which the margin is smooth is handed to :func:`guided_root` (linear
    interpolation; ``slope`` as there). Returns None when the steps leave [x_min, x_max],
    meet a non-finite margin or contradict monotonicity: the caller then brackets and runs
    Brent's method, reusing every simulation. With ``signs_only`` the no-go simulations may
    stop at the exit (margin inf, :func:`skidmc.solver.simulate` ``until_exit``): a bracket
    with such an end is never taken as smooth, and is halved.
    """
    lo = hi = None  # (x, m) of the closest no-go (m > 0) and go (m <= 0) points
    for x, m in points:
        lo, hi = _closer_bracket(lo, hi, x, m)
    # A re-search at a tighter tolerance starts from its own bracket: inside it the prior
    # says no more than the bracket does, so it is bisected in ln H.
    flat = lo is not None and hi is not None
    for _ in range(max_simulations):
        if lo is not None and hi is not None:
            if lo[0] >= hi[0]:
                return None  # not monotone at this scale: leave it to Brent
            if _is_smooth(lo, hi):
                root = lo[0] + lo[1] * (hi[0] - lo[0]) / (lo[1] - hi[1])
                return guided_root(margin, root, slope, x_tol, x_min, x_max,
                                   points=[lo, hi])
            if hi[0] - lo[0] <= 2.0 * x_tol:
                return 0.5 * (lo[0] + hi[0])
        z_lo = -math.inf if lo is None else (lo[0] - x_guess) / sigma
        z_hi = math.inf if hi is None else (hi[0] - x_guess) / sigma
        if hi is None and z_lo >= PRIOR_TAIL_Z:
            # The guess is off by more than its scatter: halving the prior's tail would creep
            # (z = 1.53, 1.85, 2.14, ...); step out in doubling multiples of z instead.
            x = x_guess + 2.0 * z_lo * sigma
        elif lo is None and z_hi <= -PRIOR_TAIL_Z:
            x = x_guess + 2.0 * z_hi * sigma
        else:
            p_lo = _STANDARD_NORMAL.cdf(z_lo) if lo is not None else 0.0
            p_hi = _STANDARD_NORMAL.cdf(z_hi) if hi is not None else 1.0
            if lo is not None and hi is not None and (flat or p_hi - p_lo < PRIOR_TAIL):
                x = 0.5 * (lo[0] + hi[0])
            else:
                x = x_guess + sigma * _STANDARD_NORMAL.inv_cdf(0.5 * (p_lo + p_hi))
        m = _margin_inside(margin, x, x_min, x_max, no_event_ok=signs_only)
        if m is None:
            return None
        lo, hi = _closer_bracket(lo, hi, x, m)
    return None


def bisection_root(margin, x_min, x_max, x_tol):
    """The report's search: geometric mean of the lowest go and the highest no-go."""
    if margin(x_max) > 0.0:
        return x_max, "above"
    if margin(x_min) <= 0.0:
        return x_min, "below"
    lo, hi = x_min, x_max
    while hi - lo > x_tol:
        mid = 0.5 * (lo + hi)
        if margin(mid) <= 0.0:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi), None


def brent_root(margin, x_min, x_max, x_tol, horizon, h_guess, overshoot=0.05):
    """Bracket the root of the margin from a first guess, then Brent's method on ln H.

    ``overshoot`` [1, in ln H] is added to each bracketing step beyond the root that the
    margin predicts (t_ev ~ 1/H): about the error of the guess. ``horizon`` [1] is
    ln(t_end / t_exit) of the model: "no event within the horizon" means m > horizon.
    """
    x = math.log(h_guess) if h_guess else 0.0  # 1 m by default
    x = min(max(x, x_min), x_max)
    lo = hi = None  # ln H of the highest no-go and the lowest go
    # Smallest bracketing step, doubled after every step: a margin that hardly depends on H
    # (e.g. a self-heating HE whose event time is set by its bulk, not by friction) still
    # reaches the search bounds within the loop.
    min_step = overshoot
    for _ in range(60):
        m = margin(x)
        if m > 0.0:
            lo = x if lo is None else max(lo, x)
        else:
            hi = x if hi is None else min(hi, x)
        if lo is not None and hi is not None:
            break
        if m > 0.0:
            if x >= x_max:
                return x_max, "above"
            # t_ev ~ 1/H: the root lies about m above; with no event in the horizon, at
            # least `horizon` above. Overshoot a little so one step usually brackets.
            step = 1.2 * m + overshoot if math.isfinite(m) else 2.0 * horizon
            x = min(x + max(step, min_step), x_max)
        else:
            if x <= x_min:
                return x_min, "below"
            x = max(x - max(-1.2 * m + overshoot, min_step), x_min)
        min_step *= 2.0
    else:  # pragma: no cover - the loop always brackets or censors within 60 steps
        raise SolverError("could not bracket the critical height")

    def bounded(xx):
        # Brent needs finite values; "no event within the horizon" means m > horizon.
        m = margin(xx)
        return m if math.isfinite(m) else 2.0 * horizon + 1.0

    from scipy.optimize import brentq  # here: importing scipy.optimize takes ~0.2-0.4 s

    x_root = brentq(bounded, lo, hi, xtol=x_tol, rtol=4 * _EPS)
    return x_root, None
