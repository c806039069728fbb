"""The thermal kernel's records (``skidmc.physics.records``) and the kernel agree.

Every field of the input record is read by the kernel and changes its outcome where it should;
every field of the output record is written; the device search fills every input field (its
record is allocated uninitialised); ``kernel_arguments`` builds the record of a model field by
field.
"""

import inspect
import re

import numpy as np
import pytest

from skidmc.physics import records, thermal
from skidmc.physics.records import KERNEL_INPUT, KERNEL_OUTPUT, kernel_input
from skidmc.physics.thermal import PREFIX_WRITE, prefix_size, simulate_kernel
from skidmc.scene import get_preset
from skidmc.solver import critical_height
from skidmc.solver.model import build_model
from skidmc.solver.simulate import kernel_arguments


def _source(function):
    return inspect.getsource(function.py_func)


def test_the_kernel_reads_every_input_field_and_writes_every_output_field():
    source = _source(thermal.simulate_core)
    read = set(re.findall(r"\binp\.(\w+)\b", source))
    written = set(re.findall(r"\bout\.(\w+) =", source))
    assert read == set(KERNEL_INPUT.names)
    assert written == set(KERNEL_OUTPUT.names)


def test_the_device_search_fills_every_input_field():
    from skidmc.solver import device

    # critical_heights_cpu allocates the run record with np.empty: a field _margin left unset
    # would be read as whatever the memory held.
    filled = set(re.findall(r"\binp\.(\w+) =", _source(device._margin)))
    assert filled == set(KERNEL_INPUT.names)


def test_kernel_input_names_what_is_missing_or_unknown():
    fields = {name: 1 if KERNEL_INPUT[name].kind == "i" else 1.5 for name in KERNEL_INPUT.names}
    record = kernel_input(**fields)[0]
    assert all(record[name] == value for name, value in fields.items())
    with pytest.raises(TypeError, match="max_steps"):
        kernel_input(**{**fields, "max_steps": 1.5})
    del fields["t_stop"]
    with pytest.raises(KeyError, match="t_stop"):
        kernel_input(**fields)
    with pytest.raises(KeyError, match="t_stopp"):
        kernel_input(**fields, t_stopp=1.0)


@pytest.fixture(scope="module")
def quartz():
    scene = get_preset("paper-quartz")
    h_c = critical_height(scene, rtol=1e-2).critical_height
    return scene, h_c


def test_kernel_arguments_build_the_models_record(quartz):
    scene, h_c = quartz
    model = build_model(scene, level=0.5, melt_width=1.0, melt_spread=1.0, target="exact")
    rec_t = np.zeros(7)
    args = kernel_arguments(model, h_c, until_exit=True, record_t=rec_t, record_tb=rec_t.copy(),
                            max_steps=1234)
    assert len(args) == len(inspect.signature(simulate_kernel.py_func).parameters)
    inp = args[3][0]
    q0 = model.flux_amplitude(h_c)
    expected = dict(
        n=model.width.shape[0], n_target=model.n_target, q_share_he=model.q_share_he,
        he_density=model.he_density, latent_heat=model.latent_heat,
        melting_point=model.melting_point, melt_width=1.0, melt_spread=1.0,
        prefactor=model.prefactor, activation_temperature=model.activation_temperature,
        heat_of_reaction=model.heat_of_reaction, q0=q0, slide_s=model.slide_s,
        slide_c=model.slide_c, omega=model.omega, t_exit=model.exit_time,
        q_ext=q0 * model.extension_flux_factor, t_end=model.end_time,
        t_stop=min(model.exit_time, model.end_time),
        initial_temperature=model.initial_temperature,
        tol_temperature=model.resolution.tol_temperature, dt_initial=model.dt_initial,
        runaway_fraction=model.runaway_fraction, max_steps=1234, n_record=7,
        target_effusivity=model.target_effusivity, he_conductivity=model.he_conductivity,
        sign_commit_fraction=thermal.SIGN_COMMIT_FRACTION, prefix_mode=0, n_table=0)
    assert set(expected) == set(KERNEL_INPUT.names)
    for name, value in expected.items():
        # Stored exactly (float64 and int64 fields); q_share_he is nan with the exact target.
        assert inp[name] == value or (np.isnan(value) and np.isnan(inp[name])), name


def _outcome(args):
    """The run's outcome as text (float.hex: equal text is equal bits, and nan equals nan)."""
    out = simulate_kernel(*args)[0]
    return tuple(float(out[name]).hex() for name in KERNEL_OUTPUT.names)


# Each field, moved by 0.1 %, must change the outcome of a go run (1.05 H_c) or of a no-event
# run (0.1 H_c, which runs on past the exit to t_stop = t_end) on a meshed target: a field the
# kernel read under another field's name, or not at all, would leave both unchanged. t_end
# alone (t_stop kept) only sets the cold-source cutoff t_cold, which moves by ~0.02 K at 0.1 %:
# no cell came that close to it in these runs, so it is moved 10x (t_cold by ~10 K).
MESHED_FIELDS = ("q_share_he", "he_density", "latent_heat", "melting_point", "melt_width",
                 "melt_spread", "prefactor", "activation_temperature", "heat_of_reaction", "q0",
                 "slide_s", "slide_c", "omega", "t_exit", "q_ext", "t_end", "t_stop",
                 "initial_temperature", "tol_temperature", "dt_initial", "runaway_fraction")
EXACT_FIELDS = ("target_effusivity", "he_conductivity")
FACTORS = {"t_end": 10.0}


@pytest.mark.parametrize("target, fields", [("mesh", MESHED_FIELDS), ("exact", EXACT_FIELDS)])
def test_every_input_field_moves_the_outcome(quartz, target, fields):
    scene, h_c = quartz
    model = build_model(scene, level=0.5, melt_width=1.0, melt_spread=1.0, target=target)
    unchanged = []
    for name in fields:
        moved = False
        for factor in (0.1, 1.05):
            args = kernel_arguments(model, factor * h_c)
            before = _outcome(args)
            args[3][name] *= FACTORS.get(name, 1.001)
            moved = moved or _outcome(args) != before
        if not moved:
            unchanged.append(name)
    assert not unchanged


def test_the_integer_and_mode_fields_act(quartz):
    scene, h_c = quartz
    model = build_model(scene, level=0.5, melt_width=1.0, melt_spread=1.0, target="exact")
    # max_steps: the cap on step attempts.
    out = simulate_kernel(*kernel_arguments(model, h_c, max_steps=17))[0]
    assert out["steps"] + out["rejected"] == 17
    # n_record: that many steps recorded, no more.
    rec_t, rec_tb = np.zeros(10), np.zeros(10)
    args = kernel_arguments(model, h_c, record_t=rec_t, record_tb=rec_tb)
    args[3]["n_record"] = 4
    simulate_kernel(*args)
    assert np.all(rec_t[:4] > 0.0) and np.all(rec_t[4:] == 0.0)
    assert np.all(rec_tb[:4] > model.initial_temperature)
    # prefix_mode: PREFIX_WRITE records a valid prefix, 0 leaves the array alone.
    for mode, valid in ((0, 0.0), (PREFIX_WRITE, 1.0)):
        prefix = np.zeros(prefix_size(model.width.shape[0]))
        simulate_kernel(*kernel_arguments(model, h_c, prefix=prefix, prefix_mode=mode))
        assert prefix[thermal._PX_VALID] == valid
    # sign_commit_fraction: a go run that needs only its sign ends earlier with the commit rule.
    plain, committed = (simulate_kernel(*kernel_arguments(
        model, 1.05 * h_c, until_exit=True, sign_commit_fraction=f))[0] for f in (0.0, None))
    assert plain["event"] and committed["event"]
    assert committed["steps"] < plain["steps"]


def test_the_state_rows_are_the_device_work_rows():
    from skidmc.solver import device

    assert device.WORK_ROWS == records.STATE_ROWS + 3
    assert (device._ROW_WIDTH, device._ROW_RHO_C, device._ROW_FACE) == (
        records.STATE_ROWS, records.STATE_ROWS + 1, records.STATE_ROWS + 2)
