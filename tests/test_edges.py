"""The edges a user hits (issue 44): no traceback, no silent wrong answer, no hang.

A regression corpus of mistakes at the command line, in study files and at the Python API. Every
command-line case runs ``python -m skidmc`` in a subprocess with a timeout (the bound: a case
that hangs fails by ``subprocess.TimeoutExpired``, not by a timing assertion) and asserts:

* no Python traceback on stderr;
* a refused input exits non-zero (2) with a message naming the option or key and its value;
* where a run is refused, no file is left behind (neither the result nor a ``.tmp``).

The classes follow the issue: runaway sizes, tracebacks at the edges, inputs that crash the
solver, silent wrong answers, misleading messages, orphaned workers, options with a hidden
meaning.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SERIES1 = ROOT / "studies" / "paper-series1.toml"

#: Seconds a refused command may take (start-up of Python, numpy and skidmc included; the
#: shared 2-CPU machine can be slow): a bound against hangs, not a timing.
BOUND = 90

SMALL = """
[study]
name = "edge"
[scene]
preset = "paper-quartz"
[uncertain.mu]
distribution = "lognorm"
s = 0.1
relative = true
source = "test"
[design]
method = "mc"
n = {n}
seed = 1
"""


def skidmc(*args, cwd=None, timeout=BOUND, stdin=subprocess.DEVNULL, shell_pipe=None):
    """``python -m skidmc ARGS`` (this tree's package first on the path); the completed
    process, after asserting that no traceback was printed."""
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src") + os.pathsep
           + os.environ.get("PYTHONPATH", "")}
    if shell_pipe is not None:  # e.g. "| head -1": a shell pipeline
        command = " ".join([sys.executable, "-m", "skidmc", *map(_quote, args)]) + shell_pipe
        proc = subprocess.run(["bash", "-o", "pipefail", "-c", command], cwd=cwd, env=env,
                              capture_output=True, text=True, timeout=timeout, stdin=stdin)
    else:
        proc = subprocess.run([sys.executable, "-m", "skidmc", *map(str, args)], cwd=cwd,
                              env=env, capture_output=True, text=True, timeout=timeout,
                              stdin=stdin)
    assert "Traceback" not in proc.stderr, proc.stderr
    return proc


def _quote(arg) -> str:
    import shlex

    return shlex.quote(str(arg))


def refused(proc, *names: str) -> str:
    """Assert exit status 2 and that stderr names each of `names`; the message."""
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    for name in names:
        assert name in proc.stderr, (name, proc.stderr)
    return proc.stderr


def leftovers(folder: Path) -> list[str]:
    """Files in `folder` other than the study files the test wrote."""
    return sorted(p.name for p in folder.iterdir() if p.suffix != ".toml")


# --- 1. runaway sizes ---------------------------------------------------------------------------


def test_a_huge_n_on_the_command_line_is_refused_at_once_with_its_size(tmp_path):
    proc = skidmc("run", SERIES1, "--out", tmp_path / "o.h5", "--n", "1000000000000",
                  cwd=tmp_path)
    message = refused(proc, "cannot fit the free disk", "n = 1000000000000", "free")
    assert "evaluations" in message and "years" in message  # samples, bytes, time
    assert leftovers(tmp_path) == []


def test_a_huge_n_in_a_study_is_refused_integer_or_float(tmp_path):
    (tmp_path / "f.toml").write_text(SMALL.format(n="1e12"))
    refused(skidmc("run", "f.toml", "--out", "o.h5", cwd=tmp_path), "design.n", "1000000000000")
    (tmp_path / "i.toml").write_text(SMALL.format(n="1000000000000"))
    refused(skidmc("run", "i.toml", "--out", "o.h5", cwd=tmp_path), "cannot fit the free disk")
    assert leftovers(tmp_path) == []


def test_a_large_run_without_a_terminal_needs_yes(tmp_path):
    # 65536 aleatory samples x 50 epistemic draws x 4 scenes: about 7 GB, hours of work
    proc = skidmc("run", SERIES1, "--out", tmp_path / "o.h5", "--n", "65536", cwd=tmp_path)
    refused(proc, "--yes", "GB", "not confirmed")
    assert "per epistemic draw" in proc.stderr  # the first line says what --n means
    assert leftovers(tmp_path) == []


def test_the_api_refuses_a_run_its_confirm_declines_and_leaves_nothing(tmp_path):
    from skidmc.ensemble.run import RunSize, RunTooLarge, execute_study

    (tmp_path / "s.toml").write_text(SMALL.format(n=8))
    seen = []

    def decline(size: RunSize) -> bool:
        seen.append(size)
        return False

    with pytest.raises(RunTooLarge, match="not confirmed"):
        execute_study(tmp_path / "s.toml", tmp_path / "o.h5", workers=1, confirm=decline)
    assert seen[0].n_rows == 8 and seen[0].bytes > 0 and seen[0].seconds > 0
    assert leftovers(tmp_path) == []


def test_an_interrupted_create_leaves_no_tmp_file(tmp_path, monkeypatch):
    from skidmc.ensemble import storage
    from skidmc.ensemble.study import load_study

    (tmp_path / "s.toml").write_text(SMALL.format(n=8))
    study = load_study(tmp_path / "s.toml")

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(storage, "_write_skeleton", interrupted)
    with pytest.raises(KeyboardInterrupt):
        storage.EnsembleFile.create(tmp_path / "o.h5", study)
    assert leftovers(tmp_path) == []


def test_the_estimated_size_is_close_to_the_created_file(tmp_path):
    # estimated_bytes is what the disk check compares with the free space: within 10 % of the
    # file that create() allocates (a few % of metadata, alignment and checksums aside).
    from skidmc.ensemble import storage
    from skidmc.ensemble.study import load_study

    study = load_study(SERIES1).with_n(64)
    f = storage.EnsembleFile.create(tmp_path / "o.h5", study)
    f.close()
    actual = (tmp_path / "o.h5").stat().st_size
    assert abs(storage.estimated_bytes(study) / actual - 1) < 0.10
