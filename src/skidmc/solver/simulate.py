"""One impact at one drop height: the thermal kernel run on a built model (report Eqs. 11-16).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from skidmc.physics.thermal import (
    _PX_VALID,
    INFO_EVENT,
    INFO_FAILED,
    INFO_NEWTON_ITERATIONS,
    INFO_REJECTED,
    INFO_RESUMED_STEPS,
    INFO_STEPS,
    INFO_T_EVENT,
    INFO_T_EXIT_MAX,
    INFO_T_MAX,
    INFO_Y_EXIT_MAX,
    PREFIX_MAX_SCALE,
    PREFIX_RESUME,
    PREFIX_WRITE,
    SIGN_COMMIT_FRACTION,
    prefix_size,
    simulate_kernel,
)

__all__ = ["MAX_STEPS", "LinearPrefix", "Simulation", "SolverError", "kernel_arguments",
           "simulate"]

MAX_STEPS = 200_000


class SolverError(RuntimeError):
    """The time integration could not proceed (step size underflow or step cap)."""


@dataclass
class Simulation:
    """Outcome of one impact at one drop height."""

    height: float            # [m]
    event: bool              # thermal event before the exit time
    event_time: float        # [s] (inf: none within the horizon)
    exit_time: float         # [s]
    margin: float            # ln(t_ev / t_exit) [1] (inf when no event in the horizon)
    steps: int
    rejected: int
    max_temperature: float   # highest HE cell temperature reached [K]
    exit_max_temperature: float  # highest HE cell temperature at t_exit [K]
    exit_max_reacted: float  # highest fraction reacted at t_exit [1]
    newton_iterations: int = 0  # Newton iterations over all step attempts (a run's cost)
    resumed_steps: int = 0   # accepted steps taken over from a linear prefix (LinearPrefix)
    times: np.ndarray | None = None                  # [s]
    interface_temperature: np.ndarray | None = None  # [K]


class LinearPrefix:
    """The linear start that the runs of one model at nearby heights share.

    Until the hottest HE cell nears the cold-source cutoff and every HE cell lies far below
    the melting step, a run's discrete equations are linear in T - T0, and its flux is
    q0(H) ~ sqrt(H) times a shape that does not depend on H: the run at another height is the
    first one's start with T - T0 and the target's flux history scaled by the ratio of flux
    amplitudes (:data:`skidmc.physics.thermal.PREFIX_MAX_SCALE`). The first run given this
    object (:func:`simulate` ``prefix=``) records its start; each later run of the same model
    within the scale resumes from it, skipping ~10-15 % of its time (docs/model.md, "Runs of
    one search share their linear start"). A later run is then the first run's steps up to
    the prefix's end, not its own: its margin differs from a run from t = 0 by the step
    sequence's error, a few 1e-6 to 1e-5 on the presets and up to ~2e-3 where a later step is
    added or rejected, as large as the margin's own jumps between nearby heights at level 0.5.
    """

    def __init__(self, model):
        self.model = model            # the one model whose runs may use it
        self.array = np.zeros(prefix_size(model.width.shape[0]))
        self.recorded_height = None   # [m]: the height of the run that recorded it

    def mode(self, height):
        """The kernel's ``prefix_mode`` for a run at ``height`` [m]."""
        if self.recorded_height is None:
            return PREFIX_WRITE
        scale = math.sqrt(height / self.recorded_height)
        return PREFIX_RESUME if 1.0 / PREFIX_MAX_SCALE <= scale <= PREFIX_MAX_SCALE else 0


def kernel_arguments(model, height, *, max_steps=MAX_STEPS, flux_override=None,
                     until_exit=False, record_t=None, record_tb=None, prefix=None,
                     prefix_mode=0, sign_commit_fraction=None):
    """The arguments of :func:`skidmc.physics.thermal.simulate_kernel` for ``model`` at
    ``height`` [m], in its order (see :func:`simulate` for the keywords; ``record_t``,
    ``record_tb``: the recording arrays, empty when None; ``prefix``: the linear prefix's
    array, ``prefix_mode`` what the kernel does with it; ``sign_commit_fraction``: the
    commit rule's fraction, by default SIGN_COMMIT_FRACTION with ``until_exit``, else 0)."""
    if sign_commit_fraction is None:
        sign_commit_fraction = SIGN_COMMIT_FRACTION if until_exit else 0.0
    if flux_override is None:
        q0 = model.flux_amplitude(height)
        flux = (q0, model.slide_s, model.slide_c, model.omega, model.exit_time,
                q0 * model.extension_flux_factor)
    else:
        flux = tuple(float(v) for v in flux_override)
    if record_t is None:
        record_t = record_tb = np.zeros(0)
    return (model.width, model.rho_c, model.face_conductance, model.n_target, model.q_share_he,
            model.he_density, model.latent_heat, model.melting_point,
            model.resolution.melt_width, model.resolution.melt_spread,
            model.prefactor, model.activation_temperature, model.heat_of_reaction,
            flux[0], flux[1], flux[2], flux[3], flux[4], flux[5], model.end_time,
            min(flux[4], model.end_time) if until_exit else model.end_time,
            model.initial_temperature, model.resolution.tol_temperature, model.dt_initial,
            model.runaway_fraction, max_steps, record_t, record_tb,
            model.target_effusivity, model.he_conductivity,
            sign_commit_fraction, np.zeros(0) if prefix is None else prefix, prefix_mode,
            model.target_table, model.target_table.shape[0] // 4)


def simulate(model, height, *, record=False, max_steps=MAX_STEPS, flux_override=None,
             until_exit=False, prefix=None):
    """Simulate the impact from drop height ``height`` [m].

    Parameters
    ----------
    model : skidmc.solver.model.SkidModel
    height : float
        Vertical drop height H [m].
    record : bool
        Keep the interface temperature history (for checks and figures).
    flux_override : tuple, optional
        ``(q0, s, c, omega, t_exit, q_ext)`` to impose another flux shape (tests).
    until_exit : bool
        Stop at the exit time instead of the horizon when no event came by then: only the
        margin's sign is wanted (a search that locates a jumping margin's root by its signs).
        The run is the full run's up to the exit, step for step; without an event by then its
        margin is inf, of the full run's sign, and its cost is ~40-60 % of the full run's on
        the no-go side of a jump (the full run goes on under the extension flux to ~1.1 t_exit).
        A go run ends at the commit temperature
        (:data:`skidmc.physics.thermal.SIGN_COMMIT_FRACTION`), 8-13 % of its attempts earlier:
        its sign is the full run's, its margin an estimate a little below the full run's
        (3e-4 on paper-gold; the guard leaves runs whose event comes within 0.3 % of the exit
        to the plain rule, so a root's neighbours keep their exact values).
    prefix : LinearPrefix, optional
        Share the linear start with the other runs of ``model`` given the same object: the
        first records it, later ones within its scale start from it. Not with ``record``,
        ``flux_override`` or another model than the prefix's (those runs start at t = 0 and
        leave it alone).

    Returns
    -------
    Simulation
    """
    n_rec = max_steps if record else 0
    rec_t = np.zeros(min(n_rec, 100_000))
    rec_tb = np.zeros_like(rec_t)
    use_prefix = (prefix is not None and prefix.model is model and not record
                  and flux_override is None)
    mode = prefix.mode(height) if use_prefix else 0
    info = simulate_kernel(*kernel_arguments(model, height, max_steps=max_steps,
                                             flux_override=flux_override,
                                             until_exit=until_exit, record_t=rec_t,
                                             record_tb=rec_tb,
                                             prefix=prefix.array if use_prefix else None,
                                             prefix_mode=mode))
    if mode == PREFIX_WRITE and prefix.array[_PX_VALID] == 1.0:
        prefix.recorded_height = float(height)
    if info[INFO_FAILED] or (info[INFO_STEPS] + info[INFO_REJECTED] >= max_steps
                             and not info[INFO_EVENT]):
        raise SolverError(
            f"time integration failed at H = {height:.6g} m after {int(info[INFO_STEPS])} "
            f"steps ({int(info[INFO_REJECTED])} rejected)")
    t_ev = info[INFO_T_EVENT]
    t_exit = model.exit_time
    steps = int(info[INFO_STEPS])
    sim = Simulation(
        height=float(height), event=bool(info[INFO_EVENT]) and t_ev <= t_exit,
        event_time=float(t_ev), exit_time=t_exit,
        margin=math.log(t_ev / t_exit) if np.isfinite(t_ev) else math.inf,
        steps=steps, rejected=int(info[INFO_REJECTED]),
        max_temperature=float(info[INFO_T_MAX]),
        exit_max_temperature=float(info[INFO_T_EXIT_MAX]),
        exit_max_reacted=float(info[INFO_Y_EXIT_MAX]),
        newton_iterations=int(info[INFO_NEWTON_ITERATIONS]),
        resumed_steps=int(info[INFO_RESUMED_STEPS]),
    )
    if record:
        n = min(steps, rec_t.shape[0])
        sim.times = rec_t[:n].copy()
        sim.interface_temperature = rec_tb[:n].copy()
    return sim
