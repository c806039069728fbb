"""Tests of the command line (skidmc.cli).

``height`` is tested against a stand-in solver module placed in ``sys.modules``, so that these
tests check the CLI's plumbing in milliseconds; one slow test runs the real solver.
"""

from __future__ import annotations

import json
import sys
import types

import pytest

from skidmc.cli import main
from skidmc.scene import SCENE_KEYS
from skidmc.scene.presets import PRESETS

FT = 0.3048  # m, exact


@pytest.fixture
def fake_solver(monkeypatch):
    """Replace ``skidmc.solver`` by a module whose critical_height records its call."""
    calls = []

    def critical_height(scene, rtol=1e-3, tier="full", h_min=1e-3, h_max=1e4):
        calls.append({"scene": scene, "rtol": rtol, "tier": tier, "h_min": h_min, "h_max": h_max})
        censored = "above" if scene.mu == 0.0 else None
        height = h_max if censored else 0.381
        return types.SimpleNamespace(
            critical_height=height, censored=censored, evaluations=13,
            flags=("stops_sliding",), wall_time=0.25,
            to_dict=lambda: {"critical_height_m": height, "error_estimate": 1e-3, "level": 2.0},
        )

    module = types.ModuleType("skidmc.solver")
    module.critical_height = critical_height
    monkeypatch.setitem(sys.modules, "skidmc.solver", module)
    return calls


def test_presets_table(capsys):
    assert main(["presets"]) == 0
    out = capsys.readouterr().out
    for name in PRESETS:
        assert name in out
    assert "28000 psi" in out and "530 degR" in out and "ASSUMPTION: billet mass 25.3 lb" in out
    assert "Pa" in out and "W/(m K)" in out


def test_presets_json_one_preset(capsys):
    assert main(["presets", "paper-gold", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert list(data) == ["paper-gold"]
    gold = data["paper-gold"]
    assert gold["values"]["angle"] == "45 deg"
    assert list(gold["si"]) == list(SCENE_KEYS)
    assert gold["si"]["tilt"] == {"value": 45.0, "units": "deg"}


def test_presets_unknown_name_exits_2(capsys):
    assert main(["presets", "paper-quarz"]) == 2
    err = capsys.readouterr().err
    assert "paper-quarz" in err and "paper-quartz" in err


def test_height_json(fake_solver, capsys):
    argv = ["height", "--preset", "paper2-quartz", "--set", "mu=0.056",
            "--set", "flow_stress=34400 psi", "--rtol", "1e-2", "--h-min", "1 ft", "--json"]
    assert main(argv) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["critical_height_m"] == 0.381
    assert data["critical_height_ft"] == pytest.approx(0.381 / FT, rel=1e-12)
    assert data["censored"] is None and data["evaluations"] == 13
    assert data["flags"] == ["stops_sliding"]
    assert data["rtol"] == 1e-2 and data["tier"] == "full"
    assert data["h_min_m"] == pytest.approx(FT, rel=1e-12)
    assert data["error_estimate"] == 1e-3  # the solver's own diagnostics come along
    assert data["scene"]["mu"] == {"value": 0.056, "units": "1"}
    assert data["scene"]["flow_stress"]["units"] == "Pa"
    assert data["overrides"] == {"mu": "0.056", "flow_stress": "34400 psi"}
    (call,) = fake_solver
    assert call["scene"].mu == 0.056 and call["rtol"] == 1e-2
    assert call["h_min"] == pytest.approx(FT, rel=1e-12)
    assert call["h_max"] == 1e4  # not given: the solver's default


def test_height_table(fake_solver, capsys):
    assert main(["height", "--preset", "paper-quartz", "--set", "he.density=1.85 g/cm^3"]) == 0
    out = capsys.readouterr().out
    assert "0.381 m" in out and "1.25 ft" in out and "stops_sliding" in out
    assert "he.density = 1.85 g/cm^3" in out


def test_height_censored(fake_solver, capsys):
    assert main(["height", "--preset", "paper-quartz", "--set", "mu=0", "--h-max", "100"]) == 0
    out = capsys.readouterr().out
    assert "> 100 m" in out and "censored" in out


@pytest.mark.parametrize(
    ("sets", "fragment"),
    [
        (["muu=0.1"], "muu"),  # unknown key
        (["he.densty=1.9 g/cm^3"], "he.densty"),
        (["flow_stress=10 in"], "flow_stress"),  # wrong dimension
        (["flow_stress=-5 psi"], "flow_stress"),  # out of range
        (["angle=95 deg"], "angle"),
        (["mu"], "--set"),  # not KEY=VALUE
    ],
)
def test_height_bad_input_exits_2_with_one_line(fake_solver, capsys, sets, fragment):
    argv = ["height", "--preset", "paper-quartz"]
    for item in sets:
        argv += ["--set", item]
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert fragment in captured.err
    assert "Traceback" not in captured.err and len(captured.err.strip().splitlines()) == 1
    assert fake_solver == []  # the solver was never called


def test_height_bad_bounds_exit_2(fake_solver, capsys):
    assert main(["height", "--preset", "paper-quartz", "--h-min", "10", "--h-max", "1"]) == 2
    assert "--h-max" in capsys.readouterr().err
    assert main(["height", "--preset", "paper-quartz", "--h-min", "1 psi"]) == 2
    assert "--h-min" in capsys.readouterr().err


def test_usage_errors_exit_2():
    with pytest.raises(SystemExit) as info:
        main(["height"])  # --preset is required
    assert info.value.code == 2
    with pytest.raises(SystemExit) as info:
        main(["height", "--preset", "paper-quartz", "--rtol", "-1"])
    assert info.value.code == 2


@pytest.mark.slow
def test_height_with_the_real_solver(capsys):
    assert main(["height", "--preset", "paper-quartz", "--rtol", "1e-2", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["censored"] is None and data["critical_height_m"] > 0
    assert data["critical_height_ft"] == pytest.approx(data["critical_height_m"] / FT)
