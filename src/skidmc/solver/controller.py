"""The adaptive controller of the default search: one compiled set of decisions for every path.

The default search (:func:`skidmc.critical_height`) brings a Richardson pair of levels
``(L - 1, L)`` within ``rtol`` by rounds: measure the pair's estimate, then apply the cheapest
fix its measured parts say will do (tighten the roots, narrow the melting width, or move the
pair up a level). That rule used to be written twice, in Python for the CPU search and in the
compiled device search (:mod:`skidmc.solver.device`, CPU threads and GPU), and every change had
to be made and validated in both. The functions here are compiled with numba and called by the
one compiled search of :mod:`skidmc.solver.adaptive`, which both the CPU search
(:func:`skidmc.solver.search._adaptive_pair`) and the device search drive (a CUDA device
function on a GPU), so the arithmetic of a decision is one text.

How a root is found is one text too (the compiled root finders of
:mod:`skidmc.solver.finders`). What remains path-specific: how a run is made
(:func:`skidmc.solver.simulate.simulate` on any model, or the device's run of a
constant-property exact target on a thread's storage), and the actions the device cannot take
(narrowing the melting width, whose bias the CPU search measures with an extra simulation, and
levels above :data:`skidmc.solver.device.DEVICE_MAX_LEVEL`): there the device hands the scene
to the CPU search.

Every function is pure arithmetic on floats (no allocation, no Python objects), in the order
the search has always computed it, so that the results are unchanged to the last bit
(``benchmarks/heights_fingerprint.py``).
"""

from __future__ import annotations

from numba import njit

from skidmc.solver.model import melt_width_floor
from skidmc.solver.plan import (
    MAX_ADAPTIVE_LEVEL,
    MAX_ROOT_TOLERANCE,
    MELT_SHARE,
    ROOT_SHARE,
    TIGHTEN_FRACTION,
    a_posteriori_error,
    jump_root_tolerances,
    pair_root_tolerance,
)

__all__ = [
    "DONE",
    "MAX_ADAPTIVE_ROUNDS",
    "MAX_NARROWINGS",
    "NARROW",
    "REFINE",
    "STOP",
    "TIGHTEN_BOTH",
    "TIGHTEN_FINE",
    "bounded_tightening",
    "first_root_tolerances",
    "next_round",
    "pair_estimate",
    "richardson_value",
    "root_error",
]

#: Most corrections (tightened roots, a narrower melting width, a finer pair) the default
#: search applies to its first Richardson pair before it reports the estimate it reached.
MAX_ADAPTIVE_ROUNDS = 8

#: Most times the melting width of one search is narrowed (:data:`NARROW`).
MAX_NARROWINGS = 2

#: Aim of :func:`bounded_tightening`: its bound on the tightened estimate [fraction of rtol].
#: The bound already takes the roots' largest move to first order; what it neglects is second
#: order in the root tolerances t (ln H against relative height, products of moves: ~t^2, with
#: t <= rtol at most 1e-2 of rtol at rtol 1e-2, 1e-3 at rtol 1e-3).
BOUNDED_AIM = 0.99
#: Smallest fine root tolerance :func:`bounded_tightening` asks for [fraction of rtol]: below it
#: the pair moves up a level. A smooth margin's root finder converges faster than linearly,
#: so a tighter root costs one or two more simulations; a jumping margin pays one simulation
#: per halving of its bracket: from its first fine tolerance (~0.2 rtol) to 0.005 rtol is ~5
#: halvings at the fine level, against the 5-6 simulations at a level ~4x dearer that such a
#: scene's refinement took (benchmarks/tail.py).
BOUNDED_MIN_ROOT = 0.005
#: Coarse to fine root tolerance where :func:`bounded_tightening` tightens both (the ratio of
#: the first pair's tolerances, :func:`first_root_tolerances`: the fine root weighs 4x).
BOUNDED_COARSE_RATIO = 2.0

#: Decisions of :func:`next_round`.
#: DONE: the estimate is within rtol. TIGHTEN_FINE: search the fine root again at a tighter
#: tolerance. TIGHTEN_BOTH: both roots. NARROW: search the pair again with a narrower melting
#: width. REFINE: move the pair up a level. STOP: nothing left that can help; the estimate stays
#: above rtol and says so.
DONE, TIGHTEN_FINE, TIGHTEN_BOTH, NARROW, REFINE, STOP = range(6)


@njit(cache=True)
def root_error(coarse_tol, fine_tol):
    """Root-finder error bound [1] of a Richardson value from its searches' tolerances
    ``coarse_tol``, ``fine_tol`` [1, in ln H]: errors d_{L-1}, d_L enter
    R = H_L + (H_L - H_{L-1}) / 3 as (4 d_L + d_{L-1}) / 3."""
    return (4.0 * fine_tol + coarse_tol) / 3.0


@njit(cache=True)
def first_root_tolerances(rtol, level, melt_width, melt_spread, exact, signs):
    """First root tolerances on ln H [1] ``(coarse, fine)`` of the pair ``(level - 1, level)``.

    Where the margin is likely to jump (``signs``): :func:`skidmc.solver.plan.jump_root_tolerances`
    (each halving of a bracket costs one simulation, so the first tolerances take the room).
    Otherwise :func:`skidmc.solver.plan.pair_root_tolerance` for the coarse root and half of it
    for the fine one, which weighs 4x in the Richardson value.
    """
    if signs:
        return jump_root_tolerances(rtol, level, melt_width, melt_spread, exact)
    coarse = pair_root_tolerance(rtol, level, melt_width, melt_spread, exact)
    return coarse, 0.5 * coarse


@njit(cache=True)
def richardson_value(h_coarse, h_fine):
    """Richardson value of a pair of critical heights [m] at levels L - 1 and L (second order).

    Returns ``(R, c)``: R = H_L + (H_L - H_{L-1}) / 3 [m] and the correction relative to it,
    c = (H_L - H_{L-1}) / (3 R) [1].
    """
    correction = (h_fine - h_coarse) / 3.0
    height = h_fine + correction
    return height, correction / height


@njit(cache=True)
def pair_estimate(correction, coarse_level, melt_spread, exact, signs, melt_bias, coarse_tol,
                  fine_tol):
    """A pair's error estimate [1], from its own correction.

    Returns ``(pair, estimate)``: the pair's a posteriori discretisation error
    (:func:`skidmc.solver.plan.a_posteriori_error` of ``correction`` [1]), and the estimate,
    that plus the melting width's bias ``melt_bias`` [1] and the root errors the tolerances
    used allow (:func:`root_error`).
    """
    pair = a_posteriori_error(correction, coarse_level, melt_spread, exact, signs)
    return pair, pair + melt_bias + root_error(coarse_tol, fine_tol)


@njit(cache=True)
def bounded_tightening(rtol, pair, melt_bias, correction, coarse_level, coarse_tol, fine_tol,
                       melt_spread, exact, signs):
    """Root tolerances that bring a pair's estimate within rtol whatever its roots move [1].

    Where the room a pair leaves (rtol less its a posteriori part ``pair`` and the melting
    width's bias ``melt_bias``) is below ROOT_SHARE rtol, :func:`next_round` used to move the
    pair up a level: a search on a level whose simulations cost ~4x the fine level's. Tightened
    roots are far cheaper, but a tightened root moves within its old tolerance and the
    correction with it, so a small room could be used up by the move. Here the move is bounded
    instead of hoped for: a root searched again at tolerance t' lies within t + t' of the old
    one (each within its tolerance of the level's root). Roots moved by relative amounts a
    (fine) and b (coarse) move the relative correction c = (H_L - H_{L-1}) / (3 R),
    R = H_L + (H_L - H_{L-1}) / 3, by (a H_L - b H_{L-1}) / (3 R) less c times R's own move
    (4 a H_L - b H_{L-1}) / (3 R): with H_L, H_{L-1} = R (1 - c), R (1 - 4 c), to first order
    at most g (a + b) / 3 with g = 1 + 8 |c|. The a posteriori part moves by at most k times
    that, k = :func:`skidmc.solver.plan.a_posteriori_error` of a unit correction (every form of
    it is k |c| or a floor, so it grows at most k per unit of |c|). The tightened estimate is
    then at most

    * fine root only (t_f -> t_f'): pair + k g (t_f + t_f') / 3 + bias + (4 t_f' + t_c) / 3;
    * both (t_c' = BOUNDED_COARSE_RATIO t_f'):
      pair + k g (t_c + t_f + t_c' + t_f') / 3 + bias + (4 t_f' + t_c') / 3,

    and t_f' is the largest that keeps that bound at BOUNDED_AIM rtol.

    Returns
    -------
    float
        t_f' > 0: tighten the fine root alone to it; -t_f' < 0: tighten both roots, the coarse
        one to BOUNDED_COARSE_RATIO t_f'; 0: neither reaches a t_f' of at least
        BOUNDED_MIN_ROOT rtol below the old one (the pair moves up a level instead).
    """
    budget = BOUNDED_AIM * rtol - pair - melt_bias
    slope = (a_posteriori_error(1.0, coarse_level, melt_spread, exact, signs)
             * (1.0 + 8.0 * abs(correction)))
    floor = BOUNDED_MIN_ROOT * rtol
    fine = (budget - slope * fine_tol / 3.0 - coarse_tol / 3.0) * 3.0 / (4.0 + slope)
    if floor <= fine < fine_tol:
        return fine
    ratio = BOUNDED_COARSE_RATIO
    both = ((budget - slope * (coarse_tol + fine_tol) / 3.0)
            * 3.0 / ((1.0 + ratio) * slope + 4.0 + ratio))
    if floor <= both < fine_tol and ratio * both < coarse_tol:
        return -both
    return 0.0


@njit(cache=True)
def next_round(rtol, estimate, pair, melt_bias, correction, height, coarse_level, coarse_tol,
               fine_tol, melt_width, narrowed, melt_spread, exact, signs):
    """What the default search does next with a pair whose estimate is ``estimate`` [1].

    Parameters
    ----------
    rtol : float
        The tolerance asked for [1].
    estimate, pair, melt_bias : float
        The pair's estimate, its a posteriori part and the melting width's bias in it [1]
        (:func:`pair_estimate`).
    correction, height : float
        The pair's relative Richardson correction [1] and value [m] (:func:`richardson_value`).
    coarse_level : float
        The pair's coarse level L - 1 (its fine level is L).
    coarse_tol, fine_tol : float
        The root tolerances used [1, in ln H].
    melt_width : float
        The melting width the pair was searched with [K].
    narrowed : int
        How many times the width was narrowed already.
    melt_spread : float
        The melting spread [1].
    exact, signs : bool
        As for :func:`skidmc.solver.plan.a_posteriori_error`.

    Returns
    -------
    action : int
        :data:`DONE`, :data:`TIGHTEN_FINE`, :data:`TIGHTEN_BOTH`, :data:`NARROW`,
        :data:`REFINE` or :data:`STOP`.
    coarse_tol, fine_tol : float
        The root tolerances of the next pair [1]: TIGHTEN_* the tightened ones; NARROW the
        first tolerances at the new width; REFINE the old fine tolerance (the fine search
        becomes the coarse one) and the new fine search's; otherwise unchanged.
    value : float
        NARROW: the new width [K], at least the coarse level's floor
        (:func:`skidmc.solver.model.melt_width_floor`; a step far narrower than a level
        resolves is badly wrong there). REFINE: the next level's root predicted from this pair
        [m] (its error is a quarter of the fine level's, which is about the correction).
        Otherwise 0.

    Notes
    -----
    The cheapest fix that the measured parts say will do:

    * the pair's own error and the width's bias leave at least ROOT_SHARE rtol: tighten the
      roots to TIGHTEN_FRACTION of what they leave (the fine search alone when that suffices:
      it weighs 4x; a tightened root moves within its old tolerance, and the correction with
      it);
    * the width's bias exceeds twice its share (MELT_SHARE rtol) and the width can narrow:
      scale the width to bring the bias to its share (the bias is first order in w);
    * the roots can be tightened to tolerances that bring the estimate within rtol however far
      they move (:func:`bounded_tightening`): tighten them (a search at the fine level instead
      of one at a level ~4x dearer);
    * otherwise move the pair up a level, up to MAX_ADAPTIVE_LEVEL (also where only a finer
      level's floor lets the width narrow further), unless the width's bias alone leaves no
      room and cannot narrow further. The new fine root's tolerance assumes the correction
      halves (it should shrink 4x).
    """
    if estimate <= rtol * (1.0 + 1e-12):
        return DONE, coarse_tol, fine_tol, 0.0
    room = rtol - pair - melt_bias
    fine_level = coarse_level + 1.0
    if room >= ROOT_SHARE * rtol * (1.0 - 1e-9):
        aim = TIGHTEN_FRACTION * room
        tight = (3.0 * aim - coarse_tol) / 4.0
        if tight >= 0.25 * aim:
            return TIGHTEN_FINE, coarse_tol, tight, 0.0
        return TIGHTEN_BOTH, aim, 0.5 * aim, 0.0
    floor = melt_width_floor(coarse_level)
    if (melt_bias > 2.0 * MELT_SHARE * rtol and narrowed < MAX_NARROWINGS
            and melt_width > floor * (1.0 + 1e-9)):
        width = max(floor, melt_width * MELT_SHARE * rtol / melt_bias)
        x_tol = pair_root_tolerance(rtol, fine_level, width, melt_spread, exact, signs)
        return NARROW, x_tol, 0.5 * x_tol, width
    tight = bounded_tightening(rtol, pair, melt_bias, correction, coarse_level, coarse_tol,
                               fine_tol, melt_spread, exact, signs)
    if tight > 0.0:
        return TIGHTEN_FINE, coarse_tol, tight, 0.0
    if tight < 0.0:
        return TIGHTEN_BOTH, -BOUNDED_COARSE_RATIO * tight, -tight, 0.0
    if fine_level + 1.0 <= MAX_ADAPTIVE_LEVEL and (
            melt_bias + ROOT_SHARE * rtol < rtol
            or (narrowed < MAX_NARROWINGS
                and melt_width > melt_width_floor(fine_level) * (1.0 + 1e-9))):
        room = (rtol - melt_bias
                - a_posteriori_error(0.5 * correction, fine_level, melt_spread, exact, signs))
        tight = min(MAX_ROOT_TOLERANCE,
                    max(0.5 * ROOT_SHARE * rtol, (3.0 * room - fine_tol) / 4.0))
        return REFINE, fine_tol, tight, height * (1.0 - 0.25 * correction)
    return STOP, coarse_tol, fine_tol, 0.0
