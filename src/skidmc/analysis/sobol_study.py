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
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path

__all__ = ["GrowthStep", "run_until_stable"]


class GrowthStep(dict):
    """One step of the growth: ``n`` (base samples), ``rows`` (per scene), ``new_rows`` (computed
    in this step), ``stable`` (per scene), ``max_half_width`` (per scene, of the indices the rule
    looks at)."""


def _copy_rows(source: Path, target_file, rows: int) -> None:
    """Copy samples ``0:rows`` of every variable of a finished file into an open new one."""
    from skidmc.analysis import open_ensemble

    ds = open_ensemble(source)  # verifies the checksums of what is copied
    target_file.write_chunk(0, rows, {spec.name: ds[spec.name].values[..., :rows]
                                      for spec in target_file.variables})


def _stability(path: Path, threshold: float, half_width: float, resamples: int,
               seed: int) -> tuple[dict, dict]:
    from skidmc.analysis import open_ensemble
    from skidmc.analysis.report import ensemble_sobol, scene_names
    from skidmc.analysis.sensitivity import interval_half_width, sobol_stable

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


def run_until_stable(study, out=None, *, workers: int | None = None, progress: bool | None = None,
                     solver: Callable | None = None, resamples: int = 1000, seed: int = 0,
                     force: bool = False,
                     log: Callable[[str], None] = print) -> list[GrowthStep]:
    """Run a ``saltelli`` study, doubling N until its Sobol' indices are stable or N = n_max.

    Parameters
    ----------
    study : Study or path
        A study whose design is ``saltelli`` with ``n_max`` (and optionally
        ``stable_threshold``, ``stable_half_width``).
    out : path, optional
        Result file (default ``results/<study>/ensemble.h5``).
    workers, progress, solver
        As :func:`skidmc.ensemble.run.execute_study`.
    resamples, seed : int
        Of the bootstrap intervals that the rule reads.
    force : bool
        Recompute from the study's N even where the result file already holds a complete run
        of this study (by default such a run is the starting point: nothing is recomputed).
        An interrupted growth step (``<out>.grow.h5``) is resumed without ``force`` when it
        belongs to this study and the N it grows to; otherwise it is discarded.
    log : callable
        Receives one line per step.

    Returns
    -------
    list of GrowthStep
        Also written to ``convergence.json`` beside the result.
    """
    from skidmc.ensemble.run import execute_study
    from skidmc.ensemble.storage import EnsembleFile, default_path, inspect_file
    from skidmc.ensemble.study import Study, load_study

    if not isinstance(study, Study):
        study = load_study(study)
    design = study.design
    if design.method != "saltelli" or not design.n_max:
        raise ValueError(f"design = {design.method!r}, n_max = {design.n_max!r}: the growth "
                         "needs a saltelli design with n_max")
    path = Path(out) if out is not None else default_path(study)
    if path.suffix != ".h5":
        path = path / "ensemble.h5"
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
                          solver=solver, command=f"skidmc run {study.file} (N = {n})")
            os.replace(grown, path)
            new_rows = rows - previous_rows
        else:
            execute_study(current, path, workers=workers, progress=progress, solver=solver,
                          force=bool(info), command=f"skidmc run {study.file} (N = {n})")
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
        force = False  # what this call computed is this study's own run
    record = {"threshold": design.stable_threshold, "half_width": design.stable_half_width,
              "n_max": design.n_max, "steps": steps, "stable": all(steps[-1]["stable"].values())}
    (path.parent / "convergence.json").write_text(json.dumps(record, indent=1) + "\n")
    return steps
