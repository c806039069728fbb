"""The plain kind: an ensemble of critical heights over a study's design.

``skidmc run`` draws the design and writes ``results/<name>/ensemble.h5`` through
:func:`skidmc.ensemble.run.execute_study` (resumable, checksummed, up to date when the study and
n match); ``skidmc report`` analyses it and writes the report
(:func:`skidmc.workflows.reporting.ensemble.write_report`). This module is also the
reference for a kind's interface (:mod:`skidmc.workflows.registry`).
"""

from __future__ import annotations

import math
from pathlib import Path

from skidmc.workflows.registry import Outcome, ReportOptions, RunOptions

__all__ = ["DESCRIPTION", "REPORT_OPTIONS", "RUN_OPTIONS", "default_out", "detect", "load",
           "report", "run"]

DESCRIPTION = "an ensemble of critical heights over a design (mc, lhs, sobol, saltelli)"
RUN_OPTIONS = frozenset({"out", "n", "resume", "force", "workers", "scheduler", "chunk_size",
                         "yes"})
REPORT_OPTIONS = frozenset({"out", "confidence"})


def detect(doc: dict) -> bool:
    """Every study file that no other kind claims."""
    return True


def load(path):
    """The validated study (:func:`skidmc.ensemble.study.load_study`, the ensemble kind's
    model: a saltelli design with ``n_max`` is the sobol kind's, refused)."""
    from skidmc.ensemble.study import load_study

    return load_study(path, kind="ensemble")


def default_out(study) -> Path:
    """``results/<name>/ensemble.h5``."""
    from skidmc.ensemble.storage import default_path

    return default_path(study)


def run(study, options: RunOptions) -> Outcome:
    """Run the study's design to its ensemble file (:func:`~skidmc.ensemble.run.execute_study`).

    The study file is passed on as given (execute_study loads it again: the file it records is
    the one named on the command line).
    """
    from skidmc.ensemble import run as run_module
    from skidmc.scene.scenes import implausible_inputs

    if not options.quiet:
        for sc in getattr(study, "scenes", ()):  # taken at their word, but flagged
            for line in implausible_inputs(sc.scene):
                options.log(f"skidmc run: warning: scene {sc.name}: {line}; the model was not "
                            "made for it and its heights may mean nothing")
    report = run_module.execute_study(
        options.study_path or study, options.out, n=options.n, workers=options.workers,
        scheduler=options.scheduler, resume=options.resume, force=options.force,
        progress=False if options.quiet else None, chunk_size=options.chunk_size,
        command=options.command, solver=options.solver, confirm=options.confirm)
    lines: list[str] = []
    if not options.quiet:
        if report.action == "up_to_date":
            lines.append(f"{report.path}: up to date (a complete run of this study, n = "
                         f"{report.n_rows}, completed {report.completed or '?'}); nothing "
                         "computed (--force recomputes it)")
        else:
            lines.append(f"{report.path}: {report.summary()}")
        lines += scene_summary_lines(report.path)
        failed = report.status_counts.get("failed", 0)
        if failed and failed < report.evaluated:
            lines.append(f"skidmc run: {failed} samples failed; see failure_reason in the file")
        lines += flag_summary_lines(report.path)
    if report.evaluated and report.status_counts.get("failed", 0) == report.evaluated:
        # nothing usable: an input the solver cannot take, most likely; exit 1 with the reasons
        lines.append(f"skidmc run: error: all {report.evaluated} evaluations failed: "
                     f"{_failure_reasons(report.path)}")
        return Outcome(1, report.path, tuple(lines))
    return Outcome(0, report.path, tuple(lines))


def _failure_reasons(path) -> str:
    """The failed samples' reasons in the file, counted."""
    from skidmc.ensemble.run import failure_counts
    from skidmc.ensemble.storage import open_ensemble

    ds = open_ensemble(path)
    failed = ds["status"].values == "failed"
    return failure_counts(ds["failure_reason"].values[failed])


def report(target, options: ReportOptions) -> Outcome:
    """Analyse an ensemble file (`target`: the file, or the study whose default file it is)."""
    return ensemble_report(target, options, default_out)


def ensemble_report(target, options: ReportOptions, default) -> Outcome:
    """The report of an ensemble file, shared by the kinds that write one (plain, sobol)."""
    from skidmc.analysis.report import EPISTEMIC_BAND
    from skidmc.ensemble.storage import open_ensemble
    from skidmc.workflows import reporting
    from skidmc.workflows.reporting.ensemble import write_report

    if isinstance(target, Path) and target.suffix != ".toml":
        path = target
    else:
        path = default(target)
        if not path.is_file():
            return Outcome(2, None, (f"skidmc report: error: {options.source}: no result yet at "
                                     f"{path}; run it first: skidmc run {options.source}",))
    ds = open_ensemble(path)
    usable = int((ds["status"].values != "failed").sum() - ds.attrs["unfinished"])
    if usable <= 0 and "failure_reason" in ds:
        from skidmc.ensemble.run import failure_counts

        failed = ds["status"].values == "failed"
        return Outcome(2, None, (f"skidmc report: error: {path}: no sample to report on: all "
                                 f"{int(failed.sum())} samples written failed ("
                                 f"{failure_counts(ds['failure_reason'].values[failed])})",))
    lines = []
    if ds.attrs["unfinished"]:
        lines.append(f"skidmc report: warning: {path}: {ds.attrs['unfinished']} samples "
                     "unfinished; the report uses the finished ones (finish with skidmc run "
                     "--resume)")
    confidence = 0.95 if options.confidence is None else options.confidence
    out = Path(options.out) if options.out else path.parent
    result = write_report(ds, out, source=options.source, confidence=confidence)
    printed = []
    for a in result["analyses"]:
        if a.fit is None:
            printed.append(f"{a.scene}: too few exact critical heights for a fit")
            continue
        est, low, high = a.predicted_h50()
        band = (f"epistemic {reporting.band(EPISTEMIC_BAND)}" if a.epistemic is not None
                else f"{reporting.level(confidence)} interval")
        line = (f"{a.scene}: H50 {est:.3g} ft ({band} {low:.3g} to {high:.3g}), sigma ln H "
                f"{a.fit.sigma:.2f}; {a.fit.verdict}")
        if a.experiment is not None:
            e = a.experimental_h50()
            shown = (f"> {e[1]:.3g}" if a.experiment.h50_qualifier == "lower_bound"
                     else f"{e[0]:.3g} [{e[1]:.3g}, {e[2]:.3g}]")
            line += f"; experiment {a.experiment.name}: {shown} ft"
        printed.append(line)
    return Outcome(0, out / "summary.md", tuple(lines), tuple(printed))


# --- the summary lines of a run ------------------------------------------------------------------


def _num(value: float) -> str:
    """3 significant digits without an exponent in the usual range of heights."""
    if 1000 <= abs(value) < 1e7:
        return f"{value:.0f}"
    return f"{value:.3g}"


def _heights(values, bounds) -> str:
    """``"60.6 to 400 m (199 to 1312 ft)"`` (or one value); bounds ``">"``/``"<"``/``""``."""
    from skidmc.scene.units import from_si

    if not all(math.isfinite(v) for v in values):
        return "-"
    m = " to ".join(f"{b}{_num(v)}" for v, b in zip(values, bounds))
    ft = " to ".join(f"{b}{_num(from_si(v, 'm', 'ft'))}" for v, b in zip(values, bounds))
    return f"{m} m ({ft} ft)"


def scene_summary_lines(path) -> list[str]:
    """One line per scene: median and 5-95 % range of the critical height, censored and failed
    counts (:func:`skidmc.ensemble.storage.summarize_file`)."""
    from skidmc.ensemble.storage import summarize_file

    summaries = summarize_file(path)
    width = max(len(s.scene) for s in summaries)
    lines = ["critical height per scene:"]
    for s in summaries:
        todo = "" if s.written == s.samples else f" ({s.samples - s.written} not computed yet)"
        lines.append(
            f"  {s.scene:<{width}}  median {_heights([s.median], [s.median_bound])}, "
            f"5-95 %: {_heights([s.p05, s.p95], s.range_bound)}; "
            f"censored {s.censored_above} above, {s.censored_below} below; "
            f"failed {s.failed} of {s.written}{todo}")
    return lines


def flag_summary_lines(path) -> list[str]:
    """The written samples flagged ``rtol_unmet`` or ``implausible_input``
    (:data:`skidmc.solver.results.RESULT_FLAG_MEANINGS`) counted per scene, after the summary of
    :func:`scene_summary_lines`; none when no sample carries either (the model's validity flags,
    routine on some targets, are counted in the report)."""
    from skidmc.ensemble.storage import summarize_file
    from skidmc.solver.results import RESULT_FLAG_MEANINGS

    flagged = [(s.scene, {f: n for f, n in s.flags.items() if f in RESULT_FLAG_MEANINGS})
               for s in summarize_file(path)]
    flagged = [(scene, flags) for scene, flags in flagged if flags]
    if not flagged:
        return []
    width = max(len(scene) for scene, _ in flagged)
    seen = sorted({f for _, flags in flagged for f in flags})
    meanings = "; ".join(f"{f}: {RESULT_FLAG_MEANINGS[f]}" for f in seen)
    return [f"skidmc run: warning: flagged samples ({meanings}):"] + [
        f"  {scene:<{width}}  " + ", ".join(f"{flag} {n}" for flag, n in flags.items())
        for scene, flags in flagged]
