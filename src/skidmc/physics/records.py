"""The thermal kernel's records: its scalar inputs, its outcome, and the rows of its work arrays.

:func:`skidmc.physics.thermal.simulate_core` takes its scalar inputs as one record of
:data:`KERNEL_INPUT` and writes its outcome into one record of :data:`KERNEL_OUTPUT` (NumPy
structured dtypes; numba passes an element of a structured array to compiled code as a
reference to its fields, on the CPU and as CUDA device code alike, where a thread holds its
records in ``cuda.local.array(1, KERNEL_RUN)``). Its per-cell state is one 2-D work array
whose rows are named by the ``STATE_*`` constants, and the exact target's flux history one
more, rows ``HISTORY_*``.

Every field is a float64 or an int64 (flags are bools), so a record's fields hold exactly the
values the kernel's positional arguments held before (the results are the same to the last bit;
``benchmarks/heights_fingerprint.py``).
"""

from __future__ import annotations

import operator
import struct

import numpy as np

__all__ = [
    "HISTORY_QL",
    "HISTORY_QR",
    "HISTORY_ROWS",
    "HISTORY_T",
    "HISTORY_WORK",
    "KERNEL_INPUT",
    "KERNEL_OUTPUT",
    "KERNEL_RUN",
    "STATE_ROWS",
    "kernel_input",
]

_F, _I, _B = np.float64, np.int64, np.bool_

#: The scalar inputs of one run (units: see :func:`skidmc.physics.thermal.simulate_kernel`).
KERNEL_INPUT = np.dtype([
    ("n", _I),                       # cells used [1]
    ("n_target", _I),                # target cells [1] (0: HE only, the exact target)
    ("q_share_he", _F),              # interface flux share into the HE, g_1 / (g_1 + g_2) [1]
    ("he_density", _F),              # [kg/m^3]
    ("latent_heat", _F),             # [J/kg] (0: no melting)
    ("melting_point", _F),           # [K]
    ("melt_width", _F),              # [K]
    ("melt_spread", _F),             # [1]
    ("prefactor", _F),               # Z [1/s]
    ("activation_temperature", _F),  # T_a [K]
    ("heat_of_reaction", _F),        # Q [J/kg]
    ("q0", _F),                      # flux amplitude [W/m^2]
    ("slide_s", _F),                 # flux shape s [1]
    ("slide_c", _F),                 # flux shape c [1]
    ("omega", _F),                   # [1/s]
    ("t_exit", _F),                  # [s]
    ("q_ext", _F),                   # flux after t_exit [W/m^2]
    ("t_end", _F),                   # horizon [s]
    ("t_stop", _F),                  # end of the integration without an event [s]
    ("initial_temperature", _F),     # T0 [K]
    ("tol_temperature", _F),         # step tolerance [K]
    ("dt_initial", _F),              # [s]
    ("runaway_fraction", _F),        # [1]
    ("max_steps", _I),               # cap on step attempts [1]
    ("n_record", _I),                # steps to record in record_t, record_tb [1]
    ("target_effusivity", _F),       # [W s^0.5 / (m^2 K)] (exact target; 0: meshed)
    ("he_conductivity", _F),         # [W/(m K)]
    ("sign_commit_fraction", _F),    # [1] (0: the runaway rule alone)
    ("prefix_mode", _I),             # 0, PREFIX_WRITE or PREFIX_RESUME
    ("n_table", _I),                 # nodes of the target's property table [1] (0: none)
], align=True)

#: The outcome of one run (written by :func:`skidmc.physics.thermal.simulate_core`).
KERNEL_OUTPUT = np.dtype([
    ("event", _B),                   # a thermal event occurred before t_stop
    ("t_event", _F),                 # event time [s] (inf when none)
    ("steps", _I),                   # accepted time steps [1]
    ("rejected", _I),                # rejected time steps [1]
    ("t_max", _F),                   # highest HE cell temperature reached [K]
    ("y_max", _F),                   # highest fraction reacted reached [1]
    ("t_final", _F),                 # time reached [s]
    ("failed", _B),                  # the integrator could not proceed (step underflow)
    ("t_exit_max", _F),              # highest HE cell temperature at t_exit [K] (nan: not reached)
    ("y_exit_max", _F),              # highest fraction reacted at t_exit [1] (nan: not reached)
    ("newton_failures", _I),         # steps rejected because Newton did not converge [1]
    ("newton_iterations", _I),       # Newton iterations, all steps [1]
    ("history_full", _B),            # the exact target's flux history ran out of room
    ("frozen_width", _B),            # the first HE cell's melting width was frozen
    ("resumed_steps", _I),           # accepted steps taken over from a linear prefix [1]
], align=True)

#: One run's input and outcome together: the record a device search thread holds
#: (:func:`skidmc.solver.device._margin` fills ``input`` and reads ``output``).
KERNEL_RUN = np.dtype([("input", KERNEL_INPUT), ("output", KERNEL_OUTPUT)], align=True)

#: Rows of the kernel's state array (shape (STATE_ROWS, >= n)): temperatures [K] of the step
#: being solved for and the last three accepted ones, volumetric enthalpies [J/m^3] (new, last,
#: the one before), fractions reacted [1] (HE cells only: the first n - n_target entries), the
#: BDF2 history terms, and the tridiagonal sweep's coefficients.
(STATE_TEMP, STATE_TEMP_PREV, STATE_TEMP_PREV2, STATE_TEMP_NEW, STATE_H, STATE_H_PREV,
 STATE_H_NEW, STATE_Y, STATE_Y_PREV, STATE_Y_NEW, STATE_HIST_H, STATE_HIST_Y, STATE_CP,
 STATE_DP) = range(14)
STATE_ROWS = 14

#: Rows of the exact target's history array (shape (HISTORY_ROWS, capacity + 1)): accepted
#: times [s], the target's flux at the start and end of each accepted step [W/m^2] (the first
#: ``capacity`` entries), and scratch.
HISTORY_T, HISTORY_QL, HISTORY_QR, HISTORY_WORK = range(4)
HISTORY_ROWS = 4


_INPUT_NAMES = KERNEL_INPUT.names
_INPUT_SET = frozenset(_INPUT_NAMES)
_INPUT_VALUES = operator.itemgetter(*_INPUT_NAMES)
# Every field is 8 bytes, so the aligned record is the fields packed in order: one struct.pack
# fills it (an int64 field refuses a float).
_INPUT_PACK = struct.Struct("=" + "".join("q" if KERNEL_INPUT[name].kind == "i" else "d"
                                          for name in _INPUT_NAMES))
assert _INPUT_PACK.size == KERNEL_INPUT.itemsize


def kernel_input(**fields):
    """A :data:`KERNEL_INPUT` array of one record, every field given by keyword [SI].

    Built once per simulation, so built fast: the fields packed in the dtype's order into a
    new buffer, ~2 us (``np.array`` of a tuple took ~5 us, field by field ~15 us, against a
    run's ~100-1000 us).

    Raises
    ------
    KeyError
        Naming the fields missing or unknown (a record with a field left unset would run on
        zeros).
    TypeError
        Naming an integer field (``n``, ``max_steps``, ...) given a float.
    """
    if len(fields) != len(_INPUT_NAMES) or not _INPUT_SET.issuperset(fields):
        missing, unknown = _INPUT_SET - fields.keys(), fields.keys() - _INPUT_SET
        raise KeyError(f"kernel_input: missing fields {sorted(missing)}, "
                       f"unknown fields {sorted(unknown)}")
    try:
        packed = _INPUT_PACK.pack(*_INPUT_VALUES(fields))
    except struct.error as exc:
        bad = {name: fields[name] for name in _INPUT_NAMES if KERNEL_INPUT[name].kind == "i"
               and not isinstance(fields[name], (int, np.integer))}
        raise TypeError(f"kernel_input: integer fields need integers, got {bad} ({exc})") from exc
    record = np.frombuffer(bytearray(packed), dtype=KERNEL_INPUT)
    if not record.flags.aligned:   # (CPython's allocator aligns to 16 bytes: not seen)
        record = record.copy()
    return record
