"""A ``saltelli`` study that grows its base sample N until the Sobol' ranking is stable.

The stopping rule (``[design] n_max`` in the study): every first-order and total index whose
interval reaches above ``stable_threshold`` (0.1) must have an interval half-width of at most
``stable_half_width`` (0.05) in every scene (:func:`skidmc.analysis.sensitivity.sobol_stable`);
otherwise N doubles, up to ``n_max``.

Growing reuses every solver run already made: SALib's scrambled Saltelli design of N base rows is
exactly the first N (d + 2) rows of the design of 2N with the same seed (tested in
``tests/test_sensitivity.py``), so the rows of the smaller run are copied into the larger file
(their results with them) and only the new rows are computed. The larger file is built beside the
result and replaces it only when complete, so an interruption loses nothing.

The kind ``sobol`` of :mod:`skidmc.workflows.registry`: a study file says ``[study] kind =
"sobol"``, or is recognised by a saltelli design with ``n_max``. ``--n`` sets the first N of
the growth (the study's ``design.n``), ``--resume`` continues an interrupted step, ``--force``
recomputes from the first N; ``--workers`` and ``--scheduler`` are those of every step.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path

from skidmc.workflows.ensemble import ensemble_report, flag_summary_lines, scene_summary_lines
from skidmc.workflows.registry import Outcome, ReportOptions, RunOptions

__all__ = ["DESCRIPTION", "REPORT_OPTIONS", "RUN_OPTIONS", "GrowthStep", "default_out", "detect",
           "growth_size", "load", "report", "run", "run_until_stable"]

DESCRIPTION = "a saltelli design whose N doubles until the Sobol' indices are stable"
RUN_OPTIONS = frozenset({"out", "n", "resume", "force", "workers", "scheduler", "chunk_size",
                         "yes"})
REPORT_OPTIONS = frozenset({"out", "confidence"})


def detect(doc: dict) -> bool:
    """A saltelli design with ``n_max`` (files without ``[study] kind``)."""
    design = doc.get("design")
    return isinstance(design, dict) and "n_max" in design and design.get("method") == "saltelli"


def load(path):
    """The validated study; it must grow (``design.n_max``)."""
    from skidmc.ensemble.study import load_study
    from skidmc.ensemble.study_model import StudyError

    study = load_study(path)
    if not study.design.n_max:
        raise StudyError(study.file, "design.n_max", None,
                         "missing: kind = 'sobol' grows a saltelli design's N up to n_max "
                         "(e.g. n_max = 4096)")
    return study


def default_out(study) -> Path:
    """``results/<name>/ensemble.h5``."""
    from skidmc.ensemble.storage import default_path

    return default_path(study)


def run(study, options: RunOptions) -> Outcome:
    """Grow the study's N until its indices are stable (:func:`run_until_stable`)."""
    from skidmc.ensemble.study_model import StudyError

    if options.n is not None:
        if options.n > study.design.n_max:
            raise StudyError(study.file, "n (--n)", options.n,
                             f"must be <= design.n_max ({study.design.n_max}): the growth "
                             "starts at N = --n")
        study = study.with_n(options.n)
    lines: list[str] = []
    log = (lambda line: None) if options.quiet else (
        lambda line: options.log(f"skidmc run: {line}"))
    steps = run_until_stable(study, options.out, workers=options.workers,
                             scheduler=options.scheduler, resume=options.resume,
                             chunk_size=options.chunk_size,
                             progress=False if options.quiet else None, solver=options.solver,
                             force=options.force, log=log, confirm=options.confirm)
    path = _result_path(study, options.out)
    stable = all(steps[-1]["stable"].values())
    if not options.quiet:
        lines.append(f"skidmc run: N = {steps[-1]['n']}: Sobol' indices "
                     f"{'stable' if stable else 'NOT stable (n_max reached)'}")
        lines += scene_summary_lines(path) + flag_summary_lines(path)
    return Outcome(0, path, tuple(lines))


def report(target, options: ReportOptions) -> Outcome:
    """The ensemble report of the grown file (Sobol' indices among it)."""
    return ensemble_report(target, options, default_out)


def _result_path(study, out) -> Path:
    path = Path(out) if out is not None else default_out(study)
    return path if path.suffix == ".h5" else path / "ensemble.h5"


class GrowthStep(dict):
    """One step of the growth: ``n`` (base samples), ``rows`` (per scene), ``new_rows`` (computed
    in this step), ``stable`` (per scene), ``max_half_width`` (per scene, of the indices the rule
    looks at)."""


def _copy_rows(source: Path, target_file, rows: int) -> None:
    """Copy samples ``0:rows`` of every variable of a finished file into an open new one."""
    from skidmc.ensemble.storage import open_ensemble

    ds = open_ensemble(source)  # verifies the checksums of what is copied
    target_file.write_chunk(0, rows, {spec.name: ds[spec.name].values[..., :rows]
                                      for spec in target_file.variables})


def _stability(path: Path, threshold: float, half_width: float, resamples: int,
               seed: int) -> tuple[dict, dict]:
    from skidmc.analysis.report import ensemble_sobol, scene_names
    from skidmc.analysis.sensitivity import interval_half_width, sobol_stable
    from skidmc.ensemble.storage import open_ensemble

    ds = open_ensemble(path)
    stable, widest = {}, {}
    for scene in scene_names(ds):
        res = ensemble_sobol(ds, scene, resamples=resamples, seed=seed)
        stable[scene] = bool(sobol_stable(res, threshold=threshold, half_width=half_width))
        relevant = []
        for index in ("S1", "ST"):
            hw = interval_half_width(res, index=index).values
            look = res[f"{index}_high"].values > threshold
            relevant += list(hw[look])
        widest[scene] = float(max(relevant)) if relevant else 0.0
    return stable, widest


def growth_size(study, path: Path, workers: int | None = None, *,
                solver: Callable | None = None, force: bool = False):
    """The size of growing `study` into `path` up to its ``n_max`` (a
    :class:`~skidmc.ensemble.run.RunSize`), before it starts, or None when nothing is left to
    compute: the rows of the largest N of the ladder (N doubling from ``design.n`` while
    <= n_max) less those a complete run of this study in `path` already holds (reused unless
    `force`); bytes for the largest step, whose grown file and the result it grows from lie
    side by side on the disk."""
    import dataclasses

    from skidmc.ensemble.run import run_size
    from skidmc.ensemble.storage import estimated_bytes, inspect_file

    design = study.design
    n_top = design.n
    while 2 * n_top <= design.n_max:
        n_top *= 2
    top = study.with_n(n_top)
    done = 0
    if not force and path.is_file():
        try:
            info = inspect_file(path)
        except Exception:  # noqa: BLE001 - a damaged file is the growth's own to report
            info = {}
        if info.get("skidmc") and info.get("complete") \
                and info.get("study_sha256") == study.sha256:
            done = min(info["n_rows"], top.n_rows)
            try:  # the growth this file ends: stable there, nothing is left to compute
                record = json.loads((path.parent / "convergence.json").read_text())
                if record.get("stable") and record["steps"][-1]["rows"] == info["n_rows"]:
                    return None
            except (OSError, ValueError, KeyError, IndexError, TypeError):
                pass
    todo = (top.n_rows - done) * len(top.scenes)
    if todo <= 0:
        return None
    size = run_size(top, path, workers, solver=solver, evaluations=todo)
    before = estimated_bytes(study.with_n(n_top // 2)) if n_top > design.n else 0
    what = (f"growing N from {design.n} up to {n_top} (n_max {design.n_max}; it stops "
            "earlier once the indices are stable), at most: ")
    return dataclasses.replace(size, bytes=size.bytes + before, what=what)


def run_until_stable(study, out=None, *, workers: int | None = None, progress: bool | None = None,
                     solver: Callable | None = None, resamples: int = 1000, seed: int = 0,
                     force: bool = False, resume: bool = False, scheduler=None,
                     chunk_size: int | None = None,
                     log: Callable[[str], None] = print,
                     confirm: Callable | None = None) -> list[GrowthStep]:
    """Run a ``saltelli`` study, doubling N until its Sobol' indices are stable or N = n_max.

    Parameters
    ----------
    study : Study or path
        A study whose design is ``saltelli`` with ``n_max`` (and optionally
        ``stable_threshold``, ``stable_half_width``).
    out : path, optional
        Result file (default ``results/<study>/ensemble.h5``).
    workers, progress, solver, scheduler, chunk_size
        As :func:`skidmc.ensemble.run.execute_study`, for every step.
    resamples, seed : int
        Of the bootstrap intervals that the rule reads.
    force : bool
        Recompute from the study's N even where the result file already holds a complete run
        of this study (by default such a run is the starting point: nothing is recomputed).
        An interrupted growth step (``<out>.grow.h5``) is resumed without ``force`` when it
        belongs to this study and the N it grows to; otherwise it is discarded.
    log : callable
        Receives one line per step.
    confirm : callable, optional
        Told the growth's size up to n_max (:func:`growth_size`) before anything is computed,
        as :func:`skidmc.ensemble.run.execute_study` tells a run's; returns whether to go on.
        A growth that cannot fit the free disk is refused whatever it says
        (:class:`~skidmc.ensemble.run.RunTooLarge`, as a refused run).

    Returns
    -------
    list of GrowthStep
        Also written to ``convergence.json`` beside the result.
    """
    from skidmc.ensemble.run import check_size, lock_output
    from skidmc.ensemble.study import Study, load_study

    if not isinstance(study, Study):
        study = load_study(study)
    design = study.design
    if design.method != "saltelli" or not design.n_max:
        raise ValueError(f"design = {design.method!r}, n_max = {design.n_max!r}: the growth "
                         "needs a saltelli design with n_max")
    path = _result_path(study, out)
    # The result is held for the whole growth (its steps' runs hold it again, nested): a
    # second run on it is refused before it touches the grown file.
    lock = lock_output(path)
    try:
        size = growth_size(study, path, workers, solver=solver, force=force)
        if size is not None:
            check_size(size, path, confirm)
        return _grow(study, path, design, workers=workers, progress=progress, solver=solver,
                     resamples=resamples, seed=seed, force=force, resume=resume,
                     scheduler=scheduler, chunk_size=chunk_size, log=log)
    finally:
        if lock is not None:
            lock.release()


def _grow(study, path, design, *, workers, progress, solver, resamples, seed, force, resume,
          scheduler, chunk_size, log) -> list[GrowthStep]:
    """The growth of :func:`run_until_stable`, its result file held and its size checked."""
    from skidmc.ensemble.run import execute_study
    from skidmc.ensemble.storage import EnsembleFile, inspect_file

    n = design.n
    grown = path.with_name(path.stem + ".grow.h5")
    if force and grown.is_file():
        # An interrupted growth of an earlier run: --force recomputes everything, so its rows
        # (perhaps of other code or another N) must not be resumed into this run.
        grown.unlink()
    info = inspect_file(path) if path.is_file() else None
    if (not force and info and info.get("skidmc") and info["complete"]
            and info.get("study_sha256") == study.sha256):
        # A complete run of this study, at some N of the ladder: start from it.
        while study.with_n(n).n_rows < info["n_rows"] and 2 * n <= design.n_max:
            n *= 2
    steps: list[GrowthStep] = []
    previous_rows = 0
    while True:
        current = study.with_n(n)
        rows = current.n_rows
        info = inspect_file(path) if path.is_file() else None
        if (not force and info and info.get("skidmc") and info["complete"]
                and info["n_rows"] == rows and info.get("study_sha256") == study.sha256):
            new_rows = 0  # this N is already computed (a rerun of the command)
        elif previous_rows:
            if grown.is_file():
                # An interrupted growth is resumed only if it is this N's of this study.
                stale = inspect_file(grown)
                if not (stale.get("skidmc") and stale["n_rows"] == rows
                        and stale.get("study_sha256") == study.sha256):
                    grown.unlink()
            if not grown.is_file():
                with EnsembleFile.create(grown, current,
                                         history=f"grown from N = {n // 2}") as f:
                    _copy_rows(path, f, previous_rows)
            execute_study(current, grown, resume=True, workers=workers, progress=progress,
                          solver=solver, scheduler=scheduler, chunk_size=chunk_size,
                          command=f"skidmc run {study.file} (N = {n})")
            os.replace(grown, path)
            new_rows = rows - previous_rows
        else:
            # A complete file of another N is replaced; an unfinished one is continued only
            # with `resume` (else execute_study refuses it, naming --resume and --force).
            replace = force or bool(info and info.get("complete")) and not resume
            execute_study(current, path, workers=workers, progress=progress, solver=solver,
                          scheduler=scheduler, chunk_size=chunk_size, resume=resume and not force,
                          force=replace, command=f"skidmc run {study.file} (N = {n})")
            new_rows = rows
        stable, widest = _stability(path, design.stable_threshold, design.stable_half_width,
                                    resamples, seed)
        step = GrowthStep(n=n, rows=rows, new_rows=new_rows, stable=stable,
                          max_half_width=widest)
        steps.append(step)
        log(f"N = {n}: {rows} rows per scene ({new_rows} new); stable: "
            + ", ".join(f"{s} {'yes' if ok else 'no'} (widest {widest[s]:.3f})"
                        for s, ok in stable.items()))
        if all(stable.values()):
            break
        if 2 * n > design.n_max:
            log(f"not stable at N = {n}: n_max = {design.n_max} reached")
            break
        previous_rows, n = rows, 2 * n
        force = resume = False  # what this call computed is this study's own run
    record = {"threshold": design.stable_threshold, "half_width": design.stable_half_width,
              "n_max": design.n_max, "steps": steps, "stable": all(steps[-1]["stable"].values())}
    from skidmc.workflows.reporting import write_json

    write_json(path.parent / "convergence.json", record)
    return steps
