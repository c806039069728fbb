"""The search's root finders, compiled, as state machines that the caller drives.

Each finder looks for the root of the margin m(x) = ln(t_ev / t_exit) on x = ln H (go <=>
m <= 0) and differs from the others in what it knows beforehand: a guess and a slope
(:func:`go_side_start`, :func:`guided_start`), a guess and its scatter
(:func:`prior_bisection_start`), nothing but a first height (:func:`brent_start`). The finders
were written as Python functions that call ``margin(x)``; here each is the same algorithm turned
inside out ("reverse communication", as in the zero finders of MINPACK and ARPACK): the finder
never runs a simulation; it says which x it wants (code :data:`ASK`, the x in the returned
value), the caller runs that simulation however it models the scene and hands the margin back
(:func:`finder_step`), until the finder answers with a root (:data:`ROOT`), a censored search
(:data:`CENSORED_ABOVE`, :data:`CENSORED_BELOW`), a hand-over (:data:`GIVE_UP`: the guided
finders' way of saying "bracket and run Brent's method") or an error.

This is what lets one set of finders serve both searches (issue 45): the CPU search
(:mod:`skidmc.solver.search`, through the thin drivers of :mod:`skidmc.solver.roots`) answers
with :func:`skidmc.solver.simulate.simulate` (linear prefix, tables, layers, runs that stop at
the exit), and the compiled device search (:mod:`skidmc.solver.device`, a CPU or GPU thread)
with its own run on the thread's storage. Nothing here allocates, raises or touches a Python
object: the whole state is one record (:data:`FINDER_STATE`) and a (2, n) array of go points,
which a GPU thread holds in its local memory.

The arithmetic is the Python finders' own, operation for operation, and is compiled without
``fastmath``, so the CPU search finds the same roots to the last bit as before the finders were
compiled (``benchmarks/heights_fingerprint.py``). Where the Python finders called a library:
Brent's method is :func:`scipy.optimize.brentq`'s variant (C. Harris's, scipy's
``Zeros/brentq.c``: the same steps and tests, in the same order), and the standard normal's
quantile is Wichura's algorithm AS 241 (PPND16, Applied Statistics 37 (1988) 477-484), which
Python's :meth:`statistics.NormalDist.inv_cdf` uses. Both are written out here because a
compiled caller cannot call back into Python; ``tests/test_finders.py`` checks them against
the library functions bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "ASK",
    "BAD_PROBABILITY",
    "CARRIED_GO_SLOPE_ERROR",
    "CENSORED_ABOVE",
    "CENSORED_BELOW",
    "DEFAULT_GO_SLOPE",
    "DEFAULT_GO_SLOPE_ERROR",
    "FAST_GUESS_ERROR",
    "FINDER_STATE",
    "FOLD_SLOPE",
    "GIVE_UP",
    "GO_AIM_BEND",
    "GO_BEND",
    "GO_MIN_SEPARATION",
    "GO_SECANT_SPAN",
    "JUMP_SLOPE",
    "NO_BRACKET",
    "NO_CONVERGENCE",
    "PRIOR_TAIL",
    "PRIOR_TAIL_Z",
    "ROOT",
    "SIGN_ERROR",
    "bisection_start",
    "brent_bracket_start",
    "brent_start",
    "finder_point",
    "finder_reset",
    "finder_step",
    "go_side_start",
    "guided_start",
    "history_slopes",
    "normal_cdf",
    "normal_quantile",
    "prior_bisection_start",
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
#: bounds the error of a root extrapolated from one fine go point (:func:`go_side_start`).
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
#: The bend a go-side run is aimed by [1]: each run aims above the secant's root by
#: GO_AIM_BEND * d_a * d_b (at least ``1.5 x_tol``), a typical bend rather than the worst one
#: (:data:`GO_BEND` still decides when a secant's root is accepted). The median, over the scenes
#: and the levels of the default pairs (0.5, 1.5 and 2.5; results/validation/go_side_bend.md),
#: of each scene and level's largest kappa is 0.66. Aimed by GO_BEND, the runs crept down on the
#: root from far above: on temperature-dependent targets, whose go side bends little (kappa
#: ~0.2), the coarse search took 6 go runs where the secant had the root to 5e-4 after 2. A run
#: aimed too low lands on the no-go side and closes a bracket, which is accepted as before:
#: it costs runs, never a root.
GO_AIM_BEND = 0.66
#: Steepest secant [1, d margin / d ln H] across a bracket of a margin that is smooth through
#: its root: t_ev ~ H^-s gives |slope| 1.1-1.35 on the go side, ~30 % less on the no-go side.
#: A jump (the event before the heating fades, or never) gives 0.3-0.5 of margin over a
#: bracket of ~1e-3 or less, hundreds; 10 separates the two at every bracket the searches use
#: (at most ~0.03 wide: a 0.3 jump is then still steeper).
JUMP_SLOPE = 10.0
#: Steepest go-side secant [1] along which :func:`go_side_start` extrapolates to the root: about
#: twice the measured 1.1-1.35. A steeper go side is approaching a fold (the event time's
#: square-root approach to where the event ceases; off-preset vertical drops, slopes ~16 within
#: 0.3 % of H_c): it bends far more than :data:`GO_BEND`, and the root is bracketed instead.
FOLD_SLOPE = 3.0
#: Prior probability inside a bracket below which :func:`prior_bisection_start` stops placing
#: its points by the prior (the guess was off by more than its scatter) and bisects in ln H.
PRIOR_TAIL = 0.01
#: One-sided, beyond this many sigma from the guess :func:`prior_bisection_start` steps out in
#: doubling multiples of its distance instead of halving the prior's tail.
PRIOR_TAIL_Z = 1.5

#: Most simulations of a guided finder (:func:`guided_start`, :func:`prior_bisection_start`)
#: when the caller gives none, and of :func:`go_side_start`.
GUIDED_MAX_SIMULATIONS = 40
GO_SIDE_MAX_SIMULATIONS = 8
#: Bracketing steps of :func:`brent_start` before it gives up (it always brackets or censors
#: well within them: each step at least doubles), and Brent iterations after it
#: (:func:`scipy.optimize.brentq`'s default ``maxiter``).
BRACKET_STEPS = 60
BRENT_ITERATIONS = 100

# What finder_step (and the *_start functions) return, with a value: the x to simulate (ASK),
# the root (ROOT), the bound (CENSORED_*), nothing (the others).
ASK, ROOT, GIVE_UP, CENSORED_ABOVE, CENSORED_BELOW = 0, 1, 2, 3, 4
# Errors (the Python finders raised): no bracket within BRACKET_STEPS; Brent's method did not
# converge within BRENT_ITERATIONS; a bracket whose ends have the same sign; a prior's
# quantile asked outside (0, 1).
NO_BRACKET, NO_CONVERGENCE, SIGN_ERROR, BAD_PROBABILITY = 5, 6, 7, 8

# Which finder the state is running.
_GO_SIDE, _GUIDED, _PRIOR, _BRACKET, _BRENT, _BISECTION = range(6)

#: One finder's whole state (a record; the go points of :func:`go_side_start` live in the
#: caller's (2, n) array ``pts``, sorted by x). ``lo`` is the highest no-go point seen
#: (m > 0), ``hi`` the lowest go point (m <= 0); ``has_*`` say whether they exist yet.
FINDER_STATE = np.dtype([
    ("mode", np.int64), ("count", np.int64), ("limit", np.int64), ("n_go", np.int64),
    ("x", np.float64), ("x_tol", np.float64), ("x_min", np.float64), ("x_max", np.float64),
    ("push", np.float64),
    ("has_lo", np.int64), ("lo_x", np.float64), ("lo_m", np.float64),
    ("has_hi", np.int64), ("hi_x", np.float64), ("hi_m", np.float64),
    # go side: the slope used, its relative error, whether it was carried from a coarser level
    ("slope", np.float64), ("slope_error", np.float64), ("known", np.int64),
    # guided: its slope, its step limit (has_step: one was given), the previous point
    ("g_slope", np.float64), ("step", np.float64), ("has_step", np.int64),
    ("has_prev", np.int64), ("prev_x", np.float64), ("prev_m", np.float64),
    # prior bisection: the prior N(guess, sigma^2), a bracket known beforehand (flat), the
    # slope handed to the guided finder, whether "no event" (inf) is a valid no-go margin
    ("guess", np.float64), ("sigma", np.float64), ("flat", np.int64),
    ("p_slope", np.float64), ("signs_only", np.int64),
    # bracketing: the horizon ln(t_end / t_exit), the overshoot of each step, the least step
    ("horizon", np.float64), ("overshoot", np.float64), ("min_step", np.float64),
    # Brent's method (scipy's brentq): previous, current and contrapoint, the last two steps
    ("xpre", np.float64), ("fpre", np.float64), ("xcur", np.float64), ("fcur", np.float64),
    ("xblk", np.float64), ("fblk", np.float64), ("spre", np.float64), ("scur", np.float64),
    ("b_xtol", np.float64), ("b_rtol", np.float64),
])

_SQRT2 = math.sqrt(2.0)


@njit(cache=True)
def _py_max(a, b):
    """Python's ``max(a, b)``: ``a`` unless ``b > a``."""
    return b if b > a else a


@njit(cache=True)
def _py_min(a, b):
    """Python's ``min(a, b)``: ``a`` unless ``b < a``."""
    return b if b < a else a


@njit(cache=True)
def normal_cdf(z):
    """The standard normal's distribution function at ``z`` [1], as
    :meth:`statistics.NormalDist.cdf` computes it (0.5 (1 + erf(z / sqrt 2)))."""
    return 0.5 * (1.0 + math.erf(z / _SQRT2))


@njit(cache=True)
def normal_quantile(p):
    """The standard normal's quantile at ``p`` in (0, 1) [1]: Wichura's AS 241 (PPND16),
    accurate to about 1e-16, as :meth:`statistics.NormalDist.inv_cdf` computes it."""
    q = p - 0.5
    if abs(q) <= 0.425:
        r = 0.180625 - q * q
        num = (((((((2.5090809287301226727e+3 * r + 3.3430575583588128105e+4) * r
                    + 6.7265770927008700853e+4) * r + 4.5921953931549871457e+4) * r
                  + 1.3731693765509461125e+4) * r + 1.9715909503065514427e+3) * r
                + 1.3314166789178437745e+2) * r + 3.3871328727963666080e+0) * q
        den = (((((((5.2264952788528545610e+3 * r + 2.8729085735721942674e+4) * r
                    + 3.9307895800092710610e+4) * r + 2.1213794301586595867e+4) * r
                  + 5.3941960214247511077e+3) * r + 6.8718700749205790830e+2) * r
                + 4.2313330701600911252e+1) * r + 1.0)
        return 0.0 + (num / den) * 1.0
    r = p if q <= 0.0 else 1.0 - p
    r = math.sqrt(-math.log(r))
    if r <= 5.0:
        r = r - 1.6
        num = (((((((7.74545014278341407640e-4 * r + 2.27238449892691845833e-2) * r
                    + 2.41780725177450611770e-1) * r + 1.27045825245236838258e+0) * r
                  + 3.64784832476320460504e+0) * r + 5.76949722146069140550e+0) * r
                + 4.63033784615654529590e+0) * r + 1.42343711074968357734e+0)
        den = (((((((1.05075007164441684324e-9 * r + 5.47593808499534494600e-4) * r
                    + 1.51986665636164571966e-2) * r + 1.48103976427480074590e-1) * r
                  + 6.89767334985100004550e-1) * r + 1.67638483018380384940e+0) * r
                + 2.05319162663775882187e+0) * r + 1.0)
    else:
        r -= 5.0
        num = (((((((2.01033439929228813265e-7 * r + 2.71155556874348757815e-5) * r
                    + 1.24266094738807843860e-3) * r + 2.65321895265761230930e-2) * r
                  + 2.96560571828504891230e-1) * r + 1.78482653991729133580e+0) * r
                + 5.46378491116411436990e+0) * r + 6.65790464350110377720e+0)
        den = (((((((2.04426310338993978564e-15 * r + 1.42151175831644588870e-7) * r
                    + 1.84631831751005468180e-5) * r + 7.86869131145613259100e-4) * r
                  + 1.48753612908506148525e-2) * r + 1.36929880922735805310e-1) * r
                + 5.99832206555887937690e-1) * r + 1.0)
    x = num / den
    if q < 0.0:
        x = -x
    return 0.0 + x * 1.0


@njit(cache=True)
def _is_smooth(lo_x, lo_m, hi_x, hi_m):
    """Whether the bracket (lo_x, lo_m > 0), (hi_x, hi_m <= 0) may be interpolated [bool].

    Its secant is no steeper than :data:`FOLD_SLOPE` (the smooth margin's |slope| is 1.1-1.35
    on the go side, ~30 % less on the no-go side). A steeper bracket holds a jump (the event
    either comes before the heating fades or not at all: secants of hundreds across brackets
    of ~1e-3, :data:`JUMP_SLOPE`) or the fold's steep approach, where linear interpolation
    inside a 4 x_tol bracket missed the root by 1.3 x_tol (alumina-vertical-5 at level 0,
    secant slope 8): it is halved to 2 x_tol instead. A no-go end without an event (inf) is
    never smooth.
    """
    return (lo_m - hi_m) <= FOLD_SLOPE * (hi_x - lo_x)


@njit(cache=True)
def _closer_bracket(s, x, m):
    """The point (x, m) into the bracket: the highest no-go point (m > 0) and the lowest go
    point (m <= 0) seen (a NaN margin changes nothing)."""
    if m > 0.0 and (s.has_lo == 0 or x > s.lo_x):
        s.has_lo, s.lo_x, s.lo_m = 1, x, m
    elif m <= 0.0 and (s.has_hi == 0 or x < s.hi_x):
        s.has_hi, s.hi_x, s.hi_m = 1, x, m


@njit(cache=True)
def _insert_go(s, pts, x, m):
    """(x, m <= 0) into the go points, kept sorted by x (then m); False when ``pts`` is full."""
    n = s.n_go
    if n >= pts.shape[1]:
        return False
    i = n
    while i > 0 and (pts[0, i - 1] > x or (pts[0, i - 1] == x and pts[1, i - 1] > m)):
        pts[0, i] = pts[0, i - 1]
        pts[1, i] = pts[1, i - 1]
        i -= 1
    pts[0, i] = x
    pts[1, i] = m
    s.n_go = n + 1
    return True


@njit(cache=True)
def finder_reset(st):
    """An empty state in ``st`` (shape (1,), dtype :data:`FINDER_STATE`; call before
    :func:`finder_point` and a ``*_start``)."""
    s = st[0]
    s.mode = _GO_SIDE
    s.count = 0
    s.limit = 0
    s.n_go = 0
    s.has_lo = 0
    s.has_hi = 0
    s.has_prev = 0
    s.has_step = 0
    s.known = 0
    s.flat = 0
    s.signs_only = 0
    s.lo_x = s.lo_m = s.hi_x = s.hi_m = math.nan


@njit(cache=True)
def finder_point(st, pts, x, m):
    """A point (x, m) known before the search starts (a search repeated at a tighter tolerance
    reuses its simulations): it enters the bracket and, when a go point, the go points.
    Returns False when ``pts`` is full (the point is then only in the bracket)."""
    s = st[0]
    _closer_bracket(s, x, m)
    if m <= 0.0:
        return _insert_go(s, pts, x, m)
    return True


@njit(cache=True)
def _ask(s, x):
    """Code and value asking for the margin at ``x``."""
    s.x = x
    return ASK, x


@njit(cache=True)
def _inside(s, x):
    return s.x_min < x < s.x_max


# ---------------------------------------------------------------- guided root (tight bracket)


@njit(cache=True)
def guided_start(st, x0, slope, x_tol, x_min, x_max, max_simulations, spread):
    """Root of the margin on ln H from a close guess ``x0``, always from a tight bracket.

    The margin is smooth but not linear near the root (its slope changes by ~30 % within
    0.5 % of H_c, and it has a kink at the root itself, where the event moves from before to
    after the exit) and carries ~1e-4 of step-size noise, so a root extrapolated from one
    side is not trusted. Steps aim past the predicted root by ``1.5 x_tol`` so that they
    bracket it; once a bracket [a, b] with m(a) > 0 >= m(b) is at most 4 x_tol wide, the
    root is the linear interpolation inside it (error below the bracket width times the
    slope's relative change, < x_tol). The first step uses ``slope`` (d margin / d ln H from
    a coarser search; -1, the t_ev ~ 1/H scaling, when NaN, not negative or infinite).

    Where the margin jumps at the root (not smooth: sliding stops before rebound, or a heating
    pulse that fades before the exit, so that the event comes before the fade or never) its
    values say nothing about where in the bracket the root lies: the bracket is halved until it
    is at most ``2 x_tol`` wide and its midpoint returned (error <= x_tol). One-sided steps are
    then limited to ``spread`` [1, in ln H] (doubled after each; NaN: no limit), the
    uncertainty of the guess, instead of following the margin's slope across the jump. The
    bracket already in ``s`` (points known beforehand, :func:`finder_point`) is kept.

    Gives up (:data:`GIVE_UP`) when a step leaves (x_min, x_max), meets a non-finite margin,
    finds the margin not monotone, or does not converge within ``max_simulations``: the caller
    then runs Brent's method on the bracket its full runs hold (or brackets from the guess).
    """
    return _guided_begin(st[0], x0, slope, x_tol, x_min, x_max, max_simulations, spread)


@njit(cache=True)
def _guided_begin(s, x0, slope, x_tol, x_min, x_max, max_simulations, spread):
    s.mode = _GUIDED
    s.x_tol, s.x_min, s.x_max = x_tol, x_min, x_max
    s.g_slope = slope if -math.inf < slope < 0.0 else -1.0
    s.push = 1.5 * x_tol
    s.has_step = 0 if math.isnan(spread) else 1
    s.step = spread
    s.has_prev = 0
    s.x = x0
    s.count = 0
    s.limit = max_simulations + 1
    return _guided_next(s)


@njit(cache=True)
def _guided_next(s):
    if s.count >= s.limit:
        return GIVE_UP, math.nan
    x = s.x
    if s.has_lo == 1 and s.has_hi == 1:
        if s.lo_x >= s.hi_x:
            return GIVE_UP, math.nan  # not monotone at this scale: leave it to Brent
        if not _is_smooth(s.lo_x, s.lo_m, s.hi_x, s.hi_m):
            if s.hi_x - s.lo_x <= 2.0 * s.x_tol:
                return ROOT, 0.5 * (s.lo_x + s.hi_x)
            x = 0.5 * (s.lo_x + s.hi_x)
        else:
            root = s.lo_x + s.lo_m * (s.hi_x - s.lo_x) / (s.lo_m - s.hi_m)
            if s.hi_x - s.lo_x <= 4.0 * s.x_tol:
                return ROOT, root
            # Shrink from the far end: step past the interpolated root, away from the
            # nearer end, so that the new point lands on the far side's sign.
            x = root - s.push if root - s.lo_x > s.hi_x - root else root + s.push
    elif s.has_prev == 1:
        # One-sided: the given slope's (or the secant's) prediction, pushed past the root.
        delta = -s.prev_m / s.g_slope + (s.push if s.prev_m > 0.0 else -s.push)
        if s.has_step == 1:
            delta = _py_max(-s.step, _py_min(s.step, delta))
            s.step *= 2.0
        x = s.prev_x + delta
    if not _inside(s, x):
        return GIVE_UP, math.nan
    s.count += 1
    return _ask(s, x)


@njit(cache=True)
def _guided_tell(s, m):
    x = s.x
    if not math.isfinite(m):
        return GIVE_UP, math.nan
    if (s.has_lo == 0 or s.has_hi == 0) and s.has_prev == 1 and x != s.prev_x:
        secant_slope = (m - s.prev_m) / (x - s.prev_x)
        if secant_slope < 0.0:
            s.g_slope = secant_slope
    _closer_bracket(s, x, m)
    s.has_prev, s.prev_x, s.prev_m = 1, x, m
    return _guided_next(s)


# ------------------------------------------------------------------ go-side extrapolation


@njit(cache=True)
def go_side_start(st, pts, x_guess, slope, x_tol, x_min, x_max, guess_error, max_simulations):
    """Root of the margin on ln H by extrapolation from its go side (m <= 0).

    For a rebound exit the margin is analytic on the go side up to the root: the event
    comes before t_exit, under the true flux, and t_ev ~ H^-s with s nearly constant (its
    secant slope changes by < 1 % over 5 % of H on the report presets). On the no-go side
    the event falls after t_exit, under the extension flux, and the margin bends (its slope
    changes by ~30 % within 0.5 % of H_c, with a kink at the root). So the root is taken from
    a secant through go points only, once the closest go point lies within ``4 x_tol`` of
    it (the extrapolation error is then that distance times the slope's relative change over
    it, far below ``x_tol``) or the secant's modelled bend error (:data:`GO_BEND`) is below
    ``x_tol / 2``. With one go point and a slope carried from a coarser level (``slope``
    negative; NaN: none, :data:`DEFAULT_GO_SLOPE`), the root is extrapolated along that slope
    and accepted when its modelled error, the distance times :data:`CARRIED_GO_SLOPE_ERROR`, is
    below ``x_tol / 2``. The secant uses the farthest go point within :data:`GO_SECANT_SPAN`,
    which keeps the margin's ~1e-5 step-size noise out of the slope.

    Each simulation aims just above the predicted root, by the prediction's typical error (at
    least ``1.5 x_tol``; a secant's by :data:`GO_AIM_BEND`, one point's by its slope's error),
    so that it lands on the go side: from a coarse level's root and slope this usually takes 2
    simulations, from the fast tier's height 3-4. A no-go point
    only bounds the root from below (and closes a bracket, accepted by linear interpolation
    when it is ``4 x_tol`` wide). A bracket across which the margin jumps or folds goes to
    :func:`guided_start`. Gives up when the steps leave (x_min, x_max), meet a non-finite
    margin, contradict monotonicity or do not converge within ``max_simulations``. Points known
    beforehand (:func:`finder_point`) are used with the new ones.
    """
    s = st[0]
    s.mode = _GO_SIDE
    s.x_tol, s.x_min, s.x_max = x_tol, x_min, x_max
    s.known = 1 if slope < 0.0 else 0
    s.slope = slope if s.known == 1 else DEFAULT_GO_SLOPE
    s.slope_error = CARRIED_GO_SLOPE_ERROR if s.known == 1 else DEFAULT_GO_SLOPE_ERROR
    s.push = 1.5 * x_tol
    s.count = 0
    s.limit = max_simulations
    return _go_side_next(s, x_guess + guess_error)


@njit(cache=True)
def _go_side_next(s, x):
    if s.count >= s.limit or not _inside(s, x):
        return GIVE_UP, math.nan
    s.count += 1
    return _ask(s, x)


@njit(cache=True)
def _bracket_interpolation(s, xa, ma):
    return s.lo_x + s.lo_m * (xa - s.lo_x) / (s.lo_m - ma)


@njit(cache=True)
def _go_side_tell(s, pts, m):
    x = s.x
    if not math.isfinite(m):
        return GIVE_UP, math.nan
    if m > 0.0:
        if s.has_lo == 0 or x > s.lo_x:
            s.has_lo, s.lo_x, s.lo_m = 1, x, m
    elif not _insert_go(s, pts, x, m):
        return GIVE_UP, math.nan
    n = s.n_go
    if n > 0 and s.has_lo == 1 and s.lo_x >= pts[0, 0]:
        return GIVE_UP, math.nan  # not monotone at this scale: leave it to Brent
    if n > 0 and s.has_lo == 1 and not _is_smooth(s.lo_x, s.lo_m, pts[0, 0], pts[1, 0]):
        # The margin jumps (or is too steep to interpolate) at the root: no extrapolation
        # holds; halve the bracket.
        s.has_hi, s.hi_x, s.hi_m = 1, pts[0, 0], pts[1, 0]
        return _guided_begin(s, 0.5 * (s.lo_x + pts[0, 0]), math.nan, s.x_tol, s.x_min,
                             s.x_max, GUIDED_MAX_SIMULATIONS, math.nan)
    push = s.push
    if n > 0:
        xa, ma = pts[0, 0], pts[1, 0]
        # The go points within GO_SECANT_SPAN of xa beyond it ("far", a run of the sorted
        # points): the closest at least GO_MIN_SEPARATION beyond xa (the smallest bend error
        # d_a d_b with the noise kept out of the slope), else the farthest.
        n_far = 0
        spaced = -1
        for i in range(1, n):
            if pts[0, i] - xa <= GO_SECANT_SPAN:
                n_far = i
                if spaced < 0 and pts[0, i] - xa >= GO_MIN_SEPARATION:
                    spaced = i
        if n_far > 0:
            j = spaced if spaced >= 0 else n_far
            xb, mb = pts[0, j], pts[1, j]
            secant = (mb - ma) / (xb - xa)
            if not secant < 0.0:
                return GIVE_UP, math.nan
            root = xa - ma / secant
            if secant < -FOLD_SLOPE:
                # Near a fold: the go side bends far more than GO_BEND allows; bracket.
                s.has_hi, s.hi_x, s.hi_m = 1, xa, ma
                return _guided_begin(s, root, math.nan, s.x_tol, s.x_min, s.x_max,
                                     GUIDED_MAX_SIMULATIONS, _py_max(push, xa - root))
            bend = GO_BEND * (xa - root) * (xb - root)
            if (xa - root <= 4.0 * s.x_tol or bend <= 0.5 * s.x_tol) and (
                    s.has_lo == 0 or root >= s.lo_x):
                return ROOT, root
            uncertainty = _py_max(push, GO_AIM_BEND * (xa - root) * (xb - root))
        else:
            root = xa - ma / s.slope
            # Extrapolating with a slope known to slope_error misses the root by about
            # slope_error (xa - root): one go point suffices when that is small.
            extrapolation_error = s.slope_error * (xa - root)
            if s.known == 1 and s.slope >= -FOLD_SLOPE and \
                    extrapolation_error <= 0.5 * s.x_tol and (s.has_lo == 0 or root >= s.lo_x):
                return ROOT, root
            uncertainty = _py_max(push, extrapolation_error)
        if s.has_lo == 1:
            if xa - s.lo_x <= 4.0 * s.x_tol:
                return ROOT, _bracket_interpolation(s, xa, ma)
            if root <= s.lo_x:
                # The go-side prediction is contradicted by a no-go point: interpolate in the
                # bracket instead.
                root = _bracket_interpolation(s, xa, ma)
                uncertainty = push
        x = root + uncertainty
        if x >= xa - 0.5 * push:
            # The prediction gives no progress: the root lies within about a push below the
            # closest go point. Step 2 pushes below it, to close a bracket 3 x_tol wide (the
            # bracket's midpoint where that is closer); halving the way to a far no-go point
            # crept up on the root from below, a run per halving. With no bracket, halve the
            # way to the root predicted from below.
            if s.has_lo == 1:
                x = _py_max(0.5 * (xa + s.lo_x), xa - 2.0 * push)
            else:
                x = 0.5 * (xa + root - uncertainty)
    else:
        # Only no-go points: t_ev ~ H^-s predicts the root above; aim past it.
        root = s.lo_x - s.lo_m / s.slope
        x = root + _py_max(push, s.slope_error * (root - s.lo_x))
    return _go_side_next(s, x)


# ---------------------------------------------------------------- prior bisection (signs)


@njit(cache=True)
def prior_bisection_start(st, pts, x_guess, sigma, x_tol, x_min, x_max, max_simulations, slope,
                          signs_only):
    """Root of a margin that may jump at its root, from a guess with a known spread.

    Where sliding stops before rebound the margin jumps at the root: its values say nothing
    about where the root lies, only their signs do. With the root's prior
    ln H ~ N(``x_guess``, ``sigma``^2) (the guess's measured scatter), each simulation is placed
    at the prior's median inside the current bracket (one end may still be missing), which
    halves the prior probability left. A bracket holding less than :data:`PRIOR_TAIL` of it, or
    one known beforehand (a re-search at a tighter tolerance, :func:`finder_point`) is bisected
    in ln H; a missing end beyond :data:`PRIOR_TAIL_Z` sigma (the guess off by more than its
    scatter) is sought in steps that double the distance from the guess. From a fast-tier guess
    with sigma = 2 % a bracket of 2 ``x_tol`` = 6e-4 takes ~7 simulations, against ~10 for
    stepping out along the margin's slope and then bisecting. A jump bracket is accepted when at
    most ``2 x_tol`` wide (its midpoint, error <= x_tol); a bracket across which the margin is
    smooth is handed to :func:`guided_start` (linear interpolation; ``slope`` as there). Gives
    up when the steps leave (x_min, x_max), meet a non-finite margin or contradict
    monotonicity. With ``signs_only`` the no-go simulations may stop at the exit (margin inf,
    :func:`skidmc.solver.simulate.simulate` ``until_exit``): a bracket with such an end is never
    smooth, and is halved.
    """
    s = st[0]
    s.mode = _PRIOR
    s.x_tol, s.x_min, s.x_max = x_tol, x_min, x_max
    s.guess, s.sigma, s.p_slope = x_guess, sigma, slope
    s.signs_only = 1 if signs_only else 0
    s.flat = 1 if (s.has_lo == 1 and s.has_hi == 1) else 0
    s.count = 0
    s.limit = max_simulations
    return _prior_next(s, pts)


@njit(cache=True)
def _prior_next(s, pts):
    if s.count >= s.limit:
        return GIVE_UP, math.nan
    has_lo, has_hi = s.has_lo == 1, s.has_hi == 1
    if has_lo and has_hi:
        if s.lo_x >= s.hi_x:
            return GIVE_UP, math.nan  # not monotone at this scale: leave it to Brent
        if _is_smooth(s.lo_x, s.lo_m, s.hi_x, s.hi_m):
            root = s.lo_x + s.lo_m * (s.hi_x - s.lo_x) / (s.lo_m - s.hi_m)
            return _guided_begin(s, root, s.p_slope, s.x_tol, s.x_min, s.x_max,
                                 GUIDED_MAX_SIMULATIONS, math.nan)
        if s.hi_x - s.lo_x <= 2.0 * s.x_tol:
            return ROOT, 0.5 * (s.lo_x + s.hi_x)
    z_lo = -math.inf if not has_lo else (s.lo_x - s.guess) / s.sigma
    z_hi = math.inf if not has_hi else (s.hi_x - s.guess) / s.sigma
    if not has_hi and z_lo >= PRIOR_TAIL_Z:
        # The guess is off by more than its scatter: halving the prior's tail would creep
        # (z = 1.53, 1.85, 2.14, ...); step out in doubling multiples of z instead.
        x = s.guess + 2.0 * z_lo * s.sigma
    elif not has_lo and z_hi <= -PRIOR_TAIL_Z:
        x = s.guess + 2.0 * z_hi * s.sigma
    else:
        p_lo = normal_cdf(z_lo) if has_lo else 0.0
        p_hi = normal_cdf(z_hi) if has_hi else 1.0
        if has_lo and has_hi and (s.flat == 1 or p_hi - p_lo < PRIOR_TAIL):
            x = 0.5 * (s.lo_x + s.hi_x)
        else:
            p = 0.5 * (p_lo + p_hi)
            if not 0.0 < p < 1.0:
                return BAD_PROBABILITY, p
            x = s.guess + s.sigma * normal_quantile(p)
    if not _inside(s, x):
        return GIVE_UP, math.nan
    s.count += 1
    return _ask(s, x)


@njit(cache=True)
def _prior_tell(s, pts, m):
    if not (math.isfinite(m) or (s.signs_only == 1 and m == math.inf)):
        return GIVE_UP, math.nan
    _closer_bracket(s, s.x, m)
    return _prior_next(s, pts)


# ------------------------------------------------------- bracketing, then Brent's method


@njit(cache=True)
def brent_start(st, x0, x_min, x_max, x_tol, horizon, overshoot):
    """Bracket the root of the margin from a first x, then Brent's method on ln H.

    ``x0`` [1]: ln of the first height (clipped to [x_min, x_max]). ``overshoot`` [1, in ln H]
    is added to each bracketing step beyond the root that the margin predicts (t_ev ~ 1/H):
    about the error of the guess; the least step starts there and doubles after every step, so
    that a margin that hardly depends on H (a self-heating HE whose event time is set by its
    bulk, not by friction) still reaches the search bounds within :data:`BRACKET_STEPS`.
    ``horizon`` [1] is ln(t_end / t_exit) of the model: "no event within the horizon" means
    m > horizon. A search whose bound x_max is no-go ends :data:`CENSORED_ABOVE` (x_min go:
    :data:`CENSORED_BELOW`). The bracket then goes to Brent's method with tolerances ``x_tol``
    and 4 eps (scipy's ``brentq``), the margin capped at 2 horizon + 1 where it is not finite.
    """
    s = st[0]
    s.mode = _BRACKET
    s.x_min, s.x_max, s.x_tol = x_min, x_max, x_tol
    s.horizon, s.overshoot, s.min_step = horizon, overshoot, overshoot
    s.has_lo = s.has_hi = 0
    s.count = 0
    s.limit = BRACKET_STEPS
    return _bracket_next(s, _py_min(_py_max(x0, x_min), x_max))


@njit(cache=True)
def brent_bracket_start(st, lo_x, lo_m, hi_x, hi_m, x_min, x_max, x_tol, horizon):
    """Brent's method on a bracket known beforehand: a no-go point (``lo_x``, ``lo_m`` > 0)
    below a go point (``hi_x``, ``hi_m`` <= 0), ln H [1] and margins [1]; otherwise as
    :func:`brent_start` after its bracketing steps (a guided finder that gave up within a
    bracket hands it on, instead of bracketing again from its first guess)."""
    s = st[0]
    s.mode = _BRACKET
    s.x_min, s.x_max, s.x_tol = x_min, x_max, x_tol
    s.horizon = horizon
    s.has_lo, s.lo_x, s.lo_m = 1, lo_x, lo_m
    s.has_hi, s.hi_x, s.hi_m = 1, hi_x, hi_m
    return _brent_begin(s)


@njit(cache=True)
def _bracket_next(s, x):
    if s.count >= s.limit:
        return NO_BRACKET, math.nan
    s.count += 1
    return _ask(s, x)


@njit(cache=True)
def _bounded(s, m):
    # Brent needs finite values; "no event within the horizon" means m > horizon.
    return m if math.isfinite(m) else 2.0 * s.horizon + 1.0


@njit(cache=True)
def _bracket_tell(s, m):
    x = s.x
    if m > 0.0:
        if s.has_lo == 0 or x > s.lo_x:
            s.has_lo, s.lo_x, s.lo_m = 1, x, m
    elif s.has_hi == 0 or x < s.hi_x:
        s.has_hi, s.hi_x, s.hi_m = 1, x, m
    if s.has_lo == 1 and s.has_hi == 1:
        return _brent_begin(s)
    if m > 0.0:
        if x >= s.x_max:
            return CENSORED_ABOVE, s.x_max
        # t_ev ~ 1/H: the root lies about m above; with no event in the horizon, at least
        # `horizon` above. Overshoot a little so one step usually brackets.
        step = 1.2 * m + s.overshoot if math.isfinite(m) else 2.0 * s.horizon
        x = _py_min(x + _py_max(step, s.min_step), s.x_max)
    else:
        if x <= s.x_min:
            return CENSORED_BELOW, s.x_min
        x = _py_max(x - _py_max(-1.2 * m + s.overshoot, s.min_step), s.x_min)
    s.min_step *= 2.0
    return _bracket_next(s, x)


@njit(cache=True)
def _brent_begin(s):
    """Brent's method on the bracket (scipy's ``brentq(f, lo, hi, xtol, 4 eps)``)."""
    s.mode = _BRENT
    s.b_xtol, s.b_rtol = s.x_tol, 4.0 * _EPS
    s.xpre, s.fpre = s.lo_x, _bounded(s, s.lo_m)
    s.xcur, s.fcur = s.hi_x, _bounded(s, s.hi_m)
    s.xblk = s.fblk = s.spre = s.scur = 0.0
    if s.fpre * s.fcur > 0.0:
        return SIGN_ERROR, math.nan
    if s.fpre == 0.0:
        return ROOT, s.xpre
    if s.fcur == 0.0:
        return ROOT, s.xcur
    s.count = 0
    s.limit = BRENT_ITERATIONS
    return _brent_next(s)


@njit(cache=True)
def _brent_next(s):
    """One iteration of Brent's method up to its next evaluation (or its end)."""
    if s.count >= s.limit:
        return NO_CONVERGENCE, s.xcur
    s.count += 1
    if s.fpre * s.fcur < 0.0:
        s.xblk, s.fblk = s.xpre, s.fpre
        s.spre = s.scur = s.xcur - s.xpre
    if abs(s.fblk) < abs(s.fcur):
        s.xpre, s.xcur, s.xblk = s.xcur, s.xblk, s.xcur
        s.fpre, s.fcur, s.fblk = s.fcur, s.fblk, s.fcur
    delta = (s.b_xtol + s.b_rtol * abs(s.xcur)) / 2.0
    sbis = (s.xblk - s.xcur) / 2.0
    if s.fcur == 0.0 or abs(sbis) < delta:
        return ROOT, s.xcur
    if abs(s.spre) > delta and abs(s.fcur) < abs(s.fpre):
        if s.xpre == s.xblk:
            stry = -s.fcur * (s.xcur - s.xpre) / (s.fcur - s.fpre)   # interpolate
        else:
            dpre = (s.fpre - s.fcur) / (s.xpre - s.xcur)             # extrapolate
            dblk = (s.fblk - s.fcur) / (s.xblk - s.xcur)
            stry = -s.fcur * (s.fblk * dblk - s.fpre * dpre) / (dblk * dpre * (s.fblk - s.fpre))
        a, b = abs(s.spre), 3.0 * abs(sbis) - delta
        if 2.0 * abs(stry) < (a if a < b else b):
            s.spre, s.scur = s.scur, stry   # good short step
        else:
            s.spre = s.scur = sbis          # bisect
    else:
        s.spre = s.scur = sbis              # bisect
    s.xpre, s.fpre = s.xcur, s.fcur
    if abs(s.scur) > delta:
        s.xcur += s.scur
    else:
        s.xcur += delta if sbis > 0.0 else -delta
    return _ask(s, s.xcur)


@njit(cache=True)
def _brent_tell(s, m):
    s.fcur = _bounded(s, m)
    return _brent_next(s)


# ------------------------------------------------------------- what a finished search says


@njit(cache=True)
def history_slopes(heights, margins, n):
    """What a finished search's history says of the margin's slope [1], for the next search.

    ``heights`` [m] and ``margins`` [1]: the search's first ``n`` simulations, sorted by
    (height, margin). Returns (``slope``, ``go_slope``), NaN where there is none:

    * ``slope``: d margin / d ln H across the history's sign change (the first no-go point,
      m > 0, followed by a go point, m <= 0, higher up); -inf where the no-go end has no event
      (margin inf: a run stopped at the exit, searched by its signs, or none within the
      horizon): the margin is taken to jump there (steeper than :data:`JUMP_SLOPE`), so the
      next search locates the root by its signs too. NaN margins are skipped.
    * ``go_slope``: d margin / d ln H between the two go points (finite m <= 0) closest to the
      root, when negative.
    """
    slope = math.nan
    x0, m0, have = 0.0, 0.0, False
    for i in range(n):
        m1 = margins[i]
        if math.isnan(m1):
            continue
        x1 = math.log(heights[i])
        if have and m0 > 0.0 >= m1 and x1 > x0:
            slope = -math.inf if m0 == math.inf else (m1 - m0) / (x1 - x0)
            break
        x0, m0, have = x1, m1, True
    go_slope = math.nan
    found = False
    xa, ma = 0.0, 0.0
    for i in range(n):
        m1 = margins[i]
        if math.isfinite(m1) and m1 <= 0.0:
            x1 = math.log(heights[i])
            if not found:
                xa, ma, found = x1, m1, True
            else:
                s = (m1 - ma) / (x1 - xa)
                if s < 0.0:
                    go_slope = s
                break
    return slope, go_slope


# ------------------------------------------------------------ the report's bisection


@njit(cache=True)
def bisection_start(st, x_min, x_max, x_tol):
    """The report's search: geometric bisection on go / no-go between the bounds.

    The margin at ``x_max`` first (no-go there: :data:`CENSORED_ABOVE`), then at ``x_min`` (go
    there: :data:`CENSORED_BELOW`); then the bracket is halved in ln H until at most ``x_tol``
    wide, and its midpoint is the root (the geometric mean of the lowest go and the highest
    no-go height)."""
    s = st[0]
    s.mode = _BISECTION
    s.x_min, s.x_max, s.x_tol = x_min, x_max, x_tol
    s.count = 0   # 0: x_max asked, 1: x_min asked, 2: halving
    return _ask(s, x_max)


@njit(cache=True)
def _bisection_tell(s, m):
    if s.count == 0:
        if m > 0.0:
            return CENSORED_ABOVE, s.x_max
        s.count = 1
        return _ask(s, s.x_min)
    if s.count == 1:
        if m <= 0.0:
            return CENSORED_BELOW, s.x_min
        s.count = 2
        s.lo_x, s.hi_x = s.x_min, s.x_max
    elif m <= 0.0:
        s.hi_x = s.x
    else:
        s.lo_x = s.x
    if s.hi_x - s.lo_x > s.x_tol:
        return _ask(s, 0.5 * (s.lo_x + s.hi_x))
    return ROOT, 0.5 * (s.lo_x + s.hi_x)


# --------------------------------------------------------------------------------- driving


@njit(cache=True)
def finder_step(st, pts, m):
    """The margin ``m`` [1] at the x last asked for; returns the finder's next (code, value):
    (:data:`ASK`, x to simulate), (:data:`ROOT`, root), (:data:`CENSORED_ABOVE` or
    :data:`CENSORED_BELOW`, the bound), (:data:`GIVE_UP`, NaN) or an error code."""
    s = st[0]
    mode = s.mode
    if mode == _GO_SIDE:
        return _go_side_tell(s, pts, m)
    if mode == _GUIDED:
        return _guided_tell(s, m)
    if mode == _PRIOR:
        return _prior_tell(s, pts, m)
    if mode == _BRACKET:
        return _bracket_tell(s, m)
    if mode == _BISECTION:
        return _bisection_tell(s, m)
    return _brent_tell(s, m)
