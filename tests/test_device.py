"""The GPU backend's search (skidmc.solver.device) against the CPU full tier, and its plumbing.

The device search is one compiled function per scene; here it runs on the CPU
(``backend="cpu"`` of :func:`skidmc.solver.cuda.critical_heights`, the very function a CUDA thread
runs) and, through numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``, in a subprocess), as the
CUDA kernel. That it compiles for a real GPU is checked by ``scripts/compile_cuda_ptx.py`` (the
``slow`` test below, where numba-cuda and NVVM are installed). Speed is measured by
``benchmarks/gpu.py``, never here.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from conftest import ROOT, TINY, subprocess_env
from test_extremes import CORNERS, H_MAX, H_MIN, ONE_AT_A_TIME

from skidmc.errors import SceneError
from skidmc.scene import get_preset, list_presets, make_scene
from skidmc.solver import critical_height
from skidmc.solver.cuda import critical_heights, solve_scenes
from skidmc.solver.device import OUT_STATUS, STATUS_CPU, STATUS_OK
from skidmc.solver.fast import SCENE_FIELDS, fast_critical_height

MATRIX = ONE_AT_A_TIME + CORNERS


def _rows(scenes):
    return np.array([[float(getattr(s, f)) for f in SCENE_FIELDS] for s in scenes])


@pytest.mark.parametrize("name", list_presets())
def test_a_device_run_is_the_cpu_search_s_model_to_the_last_bit(name):
    # The device searches the CPU default search's model (the exact target, the melting
    # spread): one run at a height is the same kernel on the same inputs, so the same margin
    # bit for bit, at a first pair's levels and at a refinement's, on the go and no-go sides,
    # run in full or stopped at the exit (a search by signs; inf where no event came by then).
    from skidmc.physics.thermal import MELT_SPREAD
    from skidmc.solver.device import device_margin
    from skidmc.solver.model import build_model
    from skidmc.solver.simulate import simulate

    scene = get_preset(name)
    (row,) = _rows([scene])
    root = critical_height(scene, rtol=1e-2).critical_height
    seen_inf = False
    for level, width in ((0.0, 4.0), (1.5, 1.0), (2.5, 1.0)):
        model = build_model(scene, level=level, target="exact", melt_spread=MELT_SPREAD,
                            melt_width=width, rtol=1e-3)
        for factor in (0.9, 0.99, 1.01, 1.1):
            x = math.log(factor * root)
            for until_exit in (False, True):
                cpu = simulate(model, math.exp(x), until_exit=until_exit).margin
                dev = device_margin(row, x, level, width, MELT_SPREAD, until_exit=until_exit)
                assert dev == cpu, (level, factor, until_exit)
                seen_inf |= dev == math.inf
    assert seen_inf   # the no-go side stopped at the exit was compared too


def test_the_thread_s_arrays_hold_what_its_search_writes():
    # _build_level meshes both media in the history's first three rows before copying the HE's
    # part to the work rows: they must hold 2 MAX_CELLS cells; the work rows the HE's cells.
    from skidmc.solver import device
    from skidmc.solver.model import level_resolution

    rows, length = device.HISTORY_SHAPE
    assert rows >= 3 and length >= 2 * device.MAX_CELLS
    assert level_resolution(device.DEVICE_MAX_LEVEL)[0] == device.MAX_CELLS


def test_the_device_plans_each_scene_as_the_cpu_search():
    # The regime (where sliding stops, where the heating fades) decides the first pair and its
    # root tolerances; the device reads it from the impact's constants.
    from skidmc.physics.mechanics import contact_pressure, impact_constants
    from skidmc.solver.device import (
        REGIME_FADING,
        REGIME_STEADY,
        REGIME_STOPS_SLIDING,
        exit_regime_code,
    )
    from skidmc.solver.options import exit_regime

    names = {REGIME_STEADY: "steady", REGIME_FADING: "fading",
             REGIME_STOPS_SLIDING: "stops_sliding"}
    scenes = [get_preset(n) for n in list_presets()] + [
        make_scene(preset=preset, **overrides) for _, preset, overrides, _, _ in MATRIX]
    seen = set()
    for scene in scenes:
        if not (scene.mu > 0.0 and scene.target_hardness > 0.0):
            continue
        omega, _, t_exit, code, s, c = impact_constants(
            scene.mu, contact_pressure(scene.flow_stress, scene.target_hardness),
            scene.billet_mass, scene.billet_diameter, scene.angle, scene.tilt)
        regime = names[exit_regime_code(s, c, omega, t_exit, code)]
        assert regime == exit_regime(scene), scene
        seen.add(regime)
    assert seen == {"steady", "fading", "stops_sliding"}


@pytest.mark.parametrize("rtol", [1e-2, 3e-3, 1e-3])
def test_device_search_is_the_cpu_search_on_the_presets(rtol):
    # One search: the device drives the CPU search's compiled root finders
    # (skidmc.solver.finders) through the same steps with the same runs (the test above, and
    # the linear prefix), so its results are the CPU search's to the last bit.
    scenes = [get_preset(name) for name in list_presets()]
    device = solve_scenes(scenes, backend="cpu", rtol=rtol)
    for scene, dev in zip(scenes, device):
        cpu = critical_height(scene, rtol=rtol)
        assert dev.method == "device"
        assert dev.censored == cpu.censored
        assert dev.critical_height == cpu.critical_height, scene
        assert dev.error_estimate == cpu.error_estimate, scene
        assert dev.evaluations == cpu.evaluations, scene
        assert dev.error_estimate <= rtol * (1.0 + 1e-9)
        assert dev.flags == cpu.flags and dev.exit_kind == cpu.exit_kind


@pytest.mark.parametrize("bound", ["h_max", "h_min"])
def test_device_search_starts_as_the_cpu_search_near_a_bound(bound):
    # A fast-tier height within its stated error (6 %) of a search bound is no first guess on
    # either path (skidmc.physics.fast.censor_near_bounds): with the bound 2 % from it, both
    # searches start elsewhere, alike, and agree to the last bit. (Before the device censored
    # its guess, all 10 of these solves differed, within tolerance.)
    for name in ("paper-quartz", "paper-gold"):
        scene = get_preset(name)
        fast = fast_critical_height(scene)
        assert fast.censored is None and fast.error_estimate > 0.02
        bounds = ({"h_max": 1.02 * fast.critical_height} if bound == "h_max" else
                  {"h_min": 0.98 * fast.critical_height, "h_max": 1e4})
        (dev,) = solve_scenes([scene], backend="cpu", rtol=1e-3, **bounds)
        cpu = critical_height(scene, rtol=1e-3, **bounds)
        assert dev.method == "device", name
        assert (dev.critical_height, dev.censored, dev.error_estimate, dev.evaluations) == (
            cpu.critical_height, cpu.censored, cpu.error_estimate, cpu.evaluations), name


def test_device_estimate_bounds_its_error_against_a_tight_solve():
    # The reported estimate is a measurement per scene: it must bound the error against a solve
    # 30x tighter (whose own error, <= 1e-4, is ~10 % of the estimates checked).
    scenes = [get_preset(name) for name in list_presets()]
    device = solve_scenes(scenes, backend="cpu", rtol=3e-3)
    for scene, dev in zip(scenes, device):
        reference = critical_height(scene, rtol=1e-4).critical_height
        assert dev.method == "device"
        assert abs(dev.critical_height / reference - 1.0) <= dev.error_estimate, scene


@pytest.mark.parametrize("rtol", [1e-2, 1e-3])
@pytest.mark.parametrize("case_id, preset, overrides, outcomes, flags", MATRIX,
                         ids=[c[0] for c in MATRIX])
def test_device_search_on_the_extremes_matrix(case_id, preset, overrides, outcomes, flags, rtol):
    # At 1e-3 more of the search runs: tightened roots, refined pairs, jumps located by signs.
    scene = make_scene(preset=preset, **overrides)
    (dev,) = solve_scenes([scene], backend="cpu", rtol=rtol, h_min=H_MIN, h_max=H_MAX)
    cpu = critical_height(scene, rtol=rtol, h_min=H_MIN, h_max=H_MAX)
    assert dev.censored == cpu.censored, case_id
    assert math.isfinite(dev.critical_height)
    if dev.method == "device":
        # the device solved it: the CPU search's result to the last bit
        assert (dev.critical_height, dev.error_estimate, dev.evaluations) == (
            cpu.critical_height, cpu.error_estimate, cpu.evaluations), case_id
    assert dev.flags == cpu.flags, case_id


def test_scenes_the_device_hands_back_are_solved_by_the_cpu_search():
    # Ignition below the melting point with melting modelled: the CPU search measures the
    # melting width's bias there, so the device search returns STATUS_CPU and solve_scenes
    # falls back; the result is then the CPU search's own.
    scene = make_scene(preset="paper-quartz", **{"kinetics.activation_temperature": 15000.0,
                                                 "kinetics.prefactor": 1e14})
    out, _ = critical_heights(_rows([scene]), 3e-3, backend="cpu")
    assert out[0, OUT_STATUS] == STATUS_CPU
    calls = []

    def fallback(s, **kwargs):
        calls.append(kwargs)
        return critical_height(s, **kwargs)

    (res,) = solve_scenes([scene], backend="cpu", rtol=3e-3, fallback=fallback)
    assert len(calls) == 1 and res.method == "brent"
    assert res.critical_height == critical_height(scene, rtol=3e-3).critical_height


def test_scenes_the_device_cannot_take_are_solved_on_threads_as_one_by_one():
    # Tabled and layered targets never reach the device; the CPU search solves them on
    # threads (its kernels release the GIL), with the numbers of a serial solve.
    scenes = [get_preset("paper-quartz"), get_preset("paper-quartz").replace(target="fused-quartz"),
              get_preset("paper-alumina-smooth").replace(target="alumina-85"),
              get_preset("paper-gold").replace(target="gold-stack-report")]
    threaded = solve_scenes(scenes, backend="cpu", rtol=1e-2, threads=2)
    serial = solve_scenes(scenes, backend="cpu", rtol=1e-2, threads=1)
    assert [r.method for r in threaded] == ["device", "brent", "brent", "brent"]
    for a, b, scene in zip(threaded, serial, scenes):
        assert a.critical_height == b.critical_height and a.error_estimate == b.error_estimate
        if a.method == "brent":
            assert a.critical_height == critical_height(scene, rtol=1e-2).critical_height
    with pytest.raises(SceneError, match="threads"):
        solve_scenes(scenes[:1], backend="cpu", threads=0)


def test_bad_options_name_the_key_and_value():
    scene = get_preset("paper-quartz")
    with pytest.raises(SceneError, match="backend"):
        critical_heights(_rows([scene]), backend="opencl")
    with pytest.raises(SceneError, match="tier"):
        solve_scenes([scene], backend="cpu", tier="fast")
    with pytest.raises(SceneError, match="level"):
        solve_scenes([scene], backend="cpu", level=2.0)
    with pytest.raises(SceneError, match="rtol"):
        critical_heights(_rows([scene]), rtol=0.7, backend="cpu")


def _run(code, cudasim):
    env = subprocess_env(ROOT / "src", ROOT / "tests")
    env.pop("NUMBA_ENABLE_CUDASIM", None)
    if cudasim:
        env["NUMBA_ENABLE_CUDASIM"] = "1"
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=env,
                          capture_output=True, text=True, timeout=600)


def test_cuda_kernel_under_the_simulator_matches_the_cpu_build():
    # The kernel's indexing, local arrays, argument order and transfers, on three scenes that
    # take different paths (rebound, stops sliding, no friction), against the same search run
    # on the CPU's threads: identical results (the simulator runs the CPU build per thread).
    code = """
        import json
        import numpy as np
        from skidmc.scene import get_preset, make_scene
        from skidmc.solver.cuda import critical_heights
        from skidmc.solver.fast import SCENE_FIELDS
        scenes = [get_preset("paper-quartz"), get_preset("paper-gold"),
                  make_scene(preset="paper-quartz", mu=0.0)]
        rows = np.array([[float(getattr(s, f)) for f in SCENE_FIELDS] for s in scenes])
        gpu, _ = critical_heights(rows, 1e-2, backend="cuda")
        cpu, _ = critical_heights(rows, 1e-2, backend="cpu")
        print(json.dumps({"gpu": gpu.tolist(), "cpu": cpu.tolist()}))
    """
    proc = _run(code, cudasim=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    gpu, cpu = np.array(result["gpu"]), np.array(result["cpu"])
    np.testing.assert_array_equal(gpu, cpu)
    assert (gpu[:, OUT_STATUS] == STATUS_OK).all()


def test_evaluate_batch_and_studies_take_the_cuda_backend_under_the_simulator(tmp_path):
    code = """
        import json
        from skidmc import evaluate_batch
        rows = [{"mu": 0.0}, {"mu": 0.2}, {"mu": 1.5}, {"mu": -1.0}]
        gpu = evaluate_batch(rows, {"rtol": 1e-2, "backend": "cuda"}, base="paper-quartz",
                             workers=2)
        cpu = evaluate_batch(rows, {"rtol": 1e-2}, base="paper-quartz")
        print(json.dumps({k: [list(map(str, getattr(r, k))) for r in (gpu, cpu)]
                          for k in ("critical_height", "status", "flags", "failure_reason")}))
    """
    proc = _run(code, cudasim=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    gpu_h, cpu_h = (np.array(v, dtype=float) for v in result["critical_height"])
    assert result["status"][0] == result["status"][1] == [
        "censored_above", "ok", "ok", "failed"]
    assert result["flags"][0] == result["flags"][1]
    assert result["failure_reason"][0] == result["failure_reason"][1]
    # The simulator's threads run the CPU build of the device search, which finds the CPU
    # search's heights to the last bit (a real GPU may move the last bits: FMA contraction).
    ok = np.isfinite(cpu_h)
    np.testing.assert_array_equal(gpu_h[ok], cpu_h[ok])

    # A study with [solver] backend = "cuda": the same samples as on the CPU.
    for backend in ("cuda", "cpu"):
        (tmp_path / f"{backend}.toml").write_text(
            TINY.replace("[solver]", f'[solver]\nbackend = "{backend}"'))
    code = f"""
        import json
        import numpy as np
        from skidmc import open_ensemble, run_study
        heights = {{}}
        for backend in ("cuda", "cpu"):
            run_study({str(tmp_path)!r} + f"/{{backend}}.toml",
                      out={str(tmp_path)!r} + f"/{{backend}}")
            ds = open_ensemble({str(tmp_path)!r} + f"/{{backend}}/ensemble.h5")
            heights[backend] = np.asarray(ds["critical_height"]).ravel().tolist()
        print(json.dumps(heights))
    """
    proc = _run(code, cudasim=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    heights = json.loads(proc.stdout.strip().splitlines()[-1])
    gpu_h, cpu_h = np.array(heights["cuda"]), np.array(heights["cpu"])
    assert gpu_h.shape == cpu_h.shape == (24,) and np.isfinite(cpu_h).all()
    np.testing.assert_array_equal(gpu_h, cpu_h)


def test_study_backend_is_checked_by_name(tmp_path):
    from skidmc import load_study
    from skidmc.ensemble.study import StudyError

    path = tmp_path / "s.toml"
    path.write_text(TINY.replace("[solver]", '[solver]\nbackend = "opencl"'))
    with pytest.raises(StudyError, match=r"solver\.backend"):
        load_study(path)
    path.write_text(TINY.replace("[solver]", '[solver]\nbackend = "cuda"\ntier = "fast"'))
    with pytest.raises(StudyError, match="full tier only"):
        load_study(path)
    path.write_text(TINY.replace("[solver]", '[solver]\nbackend = "cuda"'))
    assert load_study(path).solver.as_kwargs()["backend"] == "cuda"
    path.write_text(TINY)
    assert "backend" not in load_study(path).solver.as_kwargs()


def test_cuda_backend_without_a_gpu_says_what_is_missing_and_cpu_never_imports_it():
    code = """
        import sys
        from skidmc import evaluate_batch
        from skidmc.solver.cuda import CudaUnavailableError, cuda_status
        evaluate_batch([{"mu": 0.2}], {"rtol": 1e-2}, base="paper-quartz")
        print("cpu imported numba.cuda:", "numba.cuda" in sys.modules)
        usable, why = cuda_status()
        if usable:
            print("usable")
        else:
            from skidmc.solver.cuda import solve_scenes
            from skidmc.scene import get_preset
            try:
                solve_scenes([get_preset("paper-quartz")], backend="cuda", rtol=1e-2)
            except CudaUnavailableError as exc:
                print("error:", exc)
    """
    proc = _run(code, cudasim=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "cpu imported numba.cuda: False" in proc.stdout
    if "usable" not in proc.stdout:
        assert "error: backend='cuda' cannot run here:" in proc.stdout
        assert "GPU" in proc.stdout or "CUDA" in proc.stdout


def test_a_cuda_study_names_the_scenes_the_device_cannot_take(tmp_path, capsys):
    # Every scene of the shipped studies has a layered or temperature-dependent target, which
    # the device hands to the CPU search in the run's one process: the run says so by name
    # before it starts (here it then stops, without a GPU, or runs under one).
    from skidmc.cli import main
    from skidmc.solver.cuda import cpu_only_reason

    assert cpu_only_reason(get_preset("paper-quartz"), 1e-2) is None
    assert cpu_only_reason(get_preset("paper-quartz").replace(target="fused-quartz"),
                           1e-2) == "temperature_target"
    assert cpu_only_reason(get_preset("paper-gold").replace(target="gold-stack-report"),
                           1e-2) == "layered_target"
    study = tmp_path / "s.toml"
    study.write_text(TINY.replace('preset = "paper-alumina-smooth"',
                                  'preset = "paper-alumina-smooth"\ntarget = "alumina-85"')
                     .replace("[solver]", '[solver]\nbackend = "cuda"'))
    main(["run", str(study), "--out", str(tmp_path / "o.h5"), "--n", "2", "--yes"])
    err = capsys.readouterr().err
    assert "1 of 2 scenes cannot run on the device: alumina (temperature_target)" in err, err
    assert "quartz (" not in err


def test_the_ptx_signature_names_every_argument_of_the_thread():
    # scripts/compile_cuda_ptx.py compiles _thread with THREAD_SIGNATURE; an argument added to
    # _thread and not to the signature broke that compile on a real GPU once (13 types for 14
    # arguments), a drift no CPU test saw. Parse the signature's top-level commas.
    import inspect

    from skidmc.solver import cuda as backend

    body = backend.THREAD_SIGNATURE[len("void("):-1]
    depth, count = 0, 1
    for ch in body:
        depth += ch == "[" or -(ch == "]")
        count += ch == "," and depth == 0
    assert count == len(inspect.signature(backend._thread).parameters)
    # The arrays: rows and out are 2-D, the three tables 1-D; the rest scalars.
    assert body.count("[:, ::1]") == 2 and body.count("[::1]") == 3


@pytest.mark.slow
def test_kernel_compiles_to_ptx_for_a_real_gpu():
    pytest.importorskip("numba_cuda", reason="numba-cuda (and NVVM) are needed to build PTX")
    proc = subprocess.run([sys.executable, str(ROOT / "scripts" / "compile_cuda_ptx.py")],
                          env=subprocess_env(ROOT / "src"), capture_output=True, text=True,
                          timeout=1200)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "PTX for sm_90" in proc.stdout
