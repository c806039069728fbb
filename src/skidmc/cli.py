"""Command-line front end: ``skidmc presets``, ``skidmc materials``, ``skidmc height``,
``skidmc run``.

Every input error (:class:`skidmc.errors.SkidmcError`) ends the program with one line on stderr
and exit status 2; anything else is a bug and keeps its traceback.

Examples
--------
::

    skidmc presets
    skidmc materials
    skidmc height --preset paper-quartz
    skidmc height --preset paper-quartz --set target=steel
    skidmc height --preset paper2-quartz --set mu=0.056 --set flow_stress="34400 psi" --json
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence

from skidmc import __version__
from skidmc.errors import SceneError, SkidmcError

__all__ = ["build_parser", "main"]

# --- small helpers -------------------------------------------------------------------------------


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text!r}")
    return value


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text!r}")
    return value


def _parse_sets(items: Sequence[str]) -> dict[str, str]:
    """``["mu=0.1", "flow_stress=34400 psi"]`` -> ``{"mu": "0.1", ...}``; a later KEY wins."""
    overrides: dict[str, str] = {}
    for item in items:
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key:
            raise SceneError(
                "--set", item, "expected KEY=VALUE, e.g. --set flow_stress='34400 psi'"
            )
        if len(value) >= 2 and value[0] == value[-1] and value[0] in "'\"":
            value = value[1:-1]  # quotes that reached us (e.g. from a script that quoted twice)
        overrides[key] = value
    return overrides


def _table(rows: Sequence[Sequence[str]], indent: str = "") -> str:
    """Left-aligned columns separated by two spaces."""
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    return "\n".join(
        indent + "  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows
    )


def _json(obj) -> str:
    """JSON text in skidmc's one encoding (:func:`skidmc.workflows.reporting.dumps`: NaN as
    null, infinities as "inf"/"-inf")."""
    from skidmc.workflows.reporting import dumps

    return dumps(obj, indent=2).rstrip("\n")


def _unit_label(unit: str) -> str:
    return "" if unit in ("1", "-") else unit


def _scene_inputs(scene) -> dict[str, dict]:
    from skidmc.scene import SI_UNITS

    return {key: {"value": value, "units": SI_UNITS[key]} for key, value in scene.as_dict().items()}


#: The flag ``skidmc height`` adds where the solver's error estimate stayed above --rtol.
RTOL_UNMET = "rtol_unmet"


# --- skidmc presets ------------------------------------------------------------------------------


def _cmd_presets(args: argparse.Namespace) -> int:
    from skidmc.scene import INPUT_KEYS, PRESETS, get_preset

    names = [args.name] if args.name else list(PRESETS)
    scenes = {name: get_preset(name) for name in names}  # raises SceneError on an unknown name
    if args.json:
        out = {
            name: {
                "source": PRESETS[name]["source"],
                "notes": PRESETS[name]["notes"],
                "values": PRESETS[name]["values"],
                "si": _scene_inputs(scene),
            }
            for name, scene in scenes.items()
        }
        print(_json(out))
        return 0
    blocks = []
    for name, scene in scenes.items():
        written = PRESETS[name]["values"]
        values = scene.as_dict()
        rows = [("key", "as given", "SI value", "unit", "symbol")]
        for ik in INPUT_KEYS:
            value = values[ik.key]
            shown = value if isinstance(value, str) else f"{value:.6g}"
            rows.append((ik.key, written[ik.key], shown, _unit_label(ik.si_unit), ik.symbol))
        blocks.append(
            f"{name}\n  source: {PRESETS[name]['source']}\n  notes:  {PRESETS[name]['notes']}\n"
            + _table(rows, indent="  ")
        )
    print("\n\n".join(blocks))
    return 0


# --- skidmc materials ----------------------------------------------------------------------------


def _cmd_materials(args: argparse.Namespace) -> int:
    from skidmc.scene import MATERIALS, SI_UNITS, get_material
    from skidmc.scene.materials import TARGET_KEYS
    from skidmc.scene.units import to_si

    names = [args.name] if args.name else list(MATERIALS)
    materials = [get_material(name) for name in names]  # SceneError on an unknown name
    si = {m.name: {key: to_si(key, text, SI_UNITS[key]) for key, text in m.values.items()}
          for m in materials}
    if args.json:
        print(_json({m.name: {"description": m.description, "values": m.values,
                              "si": si[m.name], "source": m.source, "spread": m.spread}
                     for m in materials}))
        return 0
    rows = [("name", *(f"{key.split('.')[1]} [{SI_UNITS[key]}]" for key in TARGET_KEYS),
             "description")]
    rows += [(m.name, *(f"{v:.4g}" for v in si[m.name].values()), m.description)
             for m in materials]
    out = _table(rows)
    if args.name:
        m = materials[0]
        out += (f"\n\nas given: {', '.join(m.values.values())}\nsource:   {m.source}\n"
                f"spread:   {m.spread}")
    print(out + "\n\nuse as: skidmc height --preset NAME --set target=MATERIAL "
          "(a target.* key set too wins)")
    return 0


# --- skidmc height -------------------------------------------------------------------------------


def _cmd_height(args: argparse.Namespace) -> int:
    from skidmc.scene import make_scene
    from skidmc.scene.units import from_si, to_si

    overrides = _parse_sets(args.set)
    scene = make_scene(overrides, preset=args.preset)
    # Search bounds are passed only when given, so that the solver's own defaults apply otherwise.
    bounds: dict[str, float] = {}
    for name, option in (("h_min", "--h-min"), ("h_max", "--h-max")):
        text = getattr(args, name)
        if text is not None:
            bounds[name] = to_si(option, text, "m")
            if not bounds[name] > 0:
                raise SceneError(option, text, "must be > 0")
    if len(bounds) == 2 and not bounds["h_min"] < bounds["h_max"]:
        raise SceneError("--h-max", args.h_max, f"must be above --h-min ({args.h_min})")
    from skidmc.solver.search import DEFAULT_H_MAX, DEFAULT_H_MIN

    if "h_max" in bounds and "h_min" not in bounds and not DEFAULT_H_MIN < bounds["h_max"]:
        raise SceneError("--h-max", args.h_max, f"must be above the default lower bound "
                         f"{DEFAULT_H_MIN:g} m (or give a smaller --h-min)")
    if "h_min" in bounds and "h_max" not in bounds and not bounds["h_min"] < DEFAULT_H_MAX:
        raise SceneError("--h-min", args.h_min, f"must be below the default upper bound "
                         f"{DEFAULT_H_MAX:g} m (or give a larger --h-max)")

    critical_height = getattr(args, "solver", None)
    if critical_height is None:
        from skidmc.solver import critical_height
    result = critical_height(scene, rtol=args.rtol, tier=args.tier, **bounds)

    height_m = float(result.critical_height)
    from skidmc.scene.scenes import implausible_inputs

    implausible = implausible_inputs(scene)
    report = {
        "critical_height_m": height_m,
        "critical_height_ft": from_si(height_m, "m", "ft"),
        "censored": result.censored,
        "evaluations": int(result.evaluations),
        "flags": list(result.flags),
        "implausible_inputs": list(implausible),
        "wall_time_s": float(result.wall_time),
        "rtol": args.rtol,
        "tier": args.tier,
        **{f"{name}_m": value for name, value in bounds.items()},
        "preset": args.preset,
        "overrides": overrides,
        "scene": _scene_inputs(scene),
    }
    for key, value in result.to_dict().items():  # the solver's diagnostics (error estimate, ...)
        report.setdefault(key, value)
    error = report.get("error_estimate")
    if args.tier == "full" and isinstance(error, (int, float)) and math.isfinite(error) \
            and error > args.rtol * (1 + 1e-9):
        # the search refined as far as it goes (its finest level) and stopped above rtol (the
        # solver flags it itself; a stand-in solver may not)
        if RTOL_UNMET not in report["flags"]:
            report["flags"].append(RTOL_UNMET)
        report["rtol_unmet"] = {"requested": args.rtol, "achieved_estimate": float(error)}
        print(f"skidmc height: warning: --rtol {args.rtol:g} was not reached: the finest "
              f"refinement gave an error estimate of {error:.2g}; ask for --rtol {error:.1g} or "
              "more", file=sys.stderr)
    for line in implausible:  # taken at its word, but the height may mean nothing
        print(f"skidmc height: warning: {line}; the model was not made for it and the "
              "height may mean nothing", file=sys.stderr)
    if args.json:
        print(_json(report))
        return 0

    print(_height_text(report, result.censored, args, overrides))
    return 0


def _height_text(report: dict, censored: str | None, args: argparse.Namespace,
                 overrides: dict) -> str:
    """The text of ``skidmc height`` (without --json): height, error estimate, one line per
    validity flag with its meaning (:data:`skidmc.solver.FLAG_MEANINGS`)."""
    from skidmc.solver import FLAG_MEANINGS

    bound = {"above": "> ", "below": "< "}.get(censored, "")
    meaning = {
        "above": "censored: no event up to the upper search bound",
        "below": "censored: event already at the lower search bound",
    }.get(censored, "no")
    height_m, height_ft = report["critical_height_m"], report["critical_height_ft"]
    error = report.get("error_estimate", math.nan)
    error = float(error) if isinstance(error, (int, float)) else math.nan
    rows = [
        ("critical height", f"{bound}{height_m:.4g} m ({bound}{height_ft:.4g} ft)"),
        ("censored", meaning),
    ]
    if args.tier == "fast":  # no search, no simulation: an error against the full model
        if math.isfinite(error):
            typical = f"{100 * error:.2g} % (typical error of the fast tier against the full model)"
            rows.append(("error estimate", typical))
        rows.append(("model", "reduced model (fast tier), no simulation"))
    else:
        if math.isfinite(error):
            rows.append(("error estimate", f"{100 * error:.2g} % (relative, numerical)"))
        rows += [("evaluations", str(report["evaluations"])),
                 ("wall time", f"{report['wall_time_s']:.3g} s")]
    flags = report["flags"]
    from skidmc.solver.results import RESULT_FLAG_MEANINGS

    meanings = {**FLAG_MEANINGS, **RESULT_FLAG_MEANINGS}
    rows += [("flags" if i == 0 else "", f"{flag}: {meanings.get(flag, '(undocumented)')}")
             for i, flag in enumerate(flags)] or [("flags", "none")]
    rows += [("implausible" if i == 0 else "", line)
             for i, line in enumerate(report.get("implausible_inputs", ()))]
    rows += [("rtol, tier", f"{args.rtol:g}, {args.tier}"), ("preset", args.preset)]
    rows += [("set", f"{key} = {value}") for key, value in overrides.items()]
    return _table(rows)


# --- skidmc run ---------------------------------------------------------------------------------
# The ensemble layer is imported only when the subcommand runs, so that `skidmc presets` and
# `skidmc height` do not load it.


def _add_run_parser(subparsers) -> None:
    run = subparsers.add_parser(
        "run", help="run a study (TOML) over an ensemble of scenes",
        description="Run the study described in STUDY.toml and store its results. A complete "
        "result file of the same study (same text, same n) is up to date: its summary is "
        "printed and nothing is computed (--force recomputes it).",
    )
    run.add_argument("study", help="study file (TOML): an ensemble, a growing Sobol' study "
                     "or a hazard study (skidmc.workflows); an option a kind does not take is "
                     "refused, naming it")
    run.add_argument("--out", help="result file (.h5) or folder (default: "
                     "results/<study name>/, ensemble.h5 or evaluations.h5)")
    run.add_argument("--n", type=_positive_int, help="the study's n (default: the study's "
                     "design.n): samples per scene for mc/lhs/sobol; base samples N for "
                     "saltelli (N (2d+2) or N (d+2) rows per scene); aleatory samples per "
                     "epistemic draw on a nested study (n_epistemic x n rows per scene); the "
                     "first N of a growing Sobol' study; the run's first line says which "
                     "where it is not samples per scene")
    run.add_argument("--yes", action="store_true",
                     help="run a large study (over 2 GB on disk or about 6 h) without asking; "
                     "without a terminal a large run is refused unless --yes is given "
                     "(ensemble and growing Sobol' studies, whose size is that up to n_max; "
                     "the hazard kind refuses --yes)")
    run.add_argument("--workers", type=_positive_int,
                     help="parallel workers, >= 1 (default: all CPUs)")
    run.add_argument("--scheduler", metavar="{local,threads,dask,tcp://host:port}",
                     help="where samples are evaluated: local (worker processes on this "
                     "machine, the default), threads (--workers threads of this process: no "
                     "start-up, but a crash in one sample ends the run), dask (a local dask "
                     "cluster of --workers processes) or tcp://host:port (a running dask "
                     "scheduler)")
    again = run.add_mutually_exclusive_group()
    again.add_argument("--resume", action="store_true", help="finish an interrupted run")
    again.add_argument("--force", action="store_true",
                       help="recompute although the result file exists (this study's, any "
                       "version, or a damaged one); the old file is replaced only once the new "
                       "one is complete")
    run.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    run.add_argument("--chunk-size", type=_positive_int, help=argparse.SUPPRESS)
    run.set_defaults(func=_cmd_run)


#: ``--workers`` above this many times the CPUs available draws a warning.
WORKERS_PER_CPU_WARNING = 2


def _finish(name: str, outcome) -> int:
    """Print a kind's :class:`~skidmc.workflows.registry.Outcome`; its exit status."""
    for line in outcome.lines:
        print(line, file=sys.stderr)
    for line in outcome.printed:
        print(line)
    if outcome.path is not None and outcome.status == 0:
        print(outcome.path)
    return outcome.status


#: A run estimated at this many seconds or bytes or more prints its size before it starts (a
#: smaller one just runs).
SIZE_LINE_SECONDS = 10.0
SIZE_LINE_BYTES = 100 * 1000**2


def _n_meaning(study) -> str:
    """What the study's n is: one line for the run's first line (``--n`` has several
    meanings)."""
    d = study.design
    if d.n_epistemic:
        return (f"n = {d.n} aleatory samples per epistemic draw, {d.n_epistemic} epistemic "
                f"draws: {study.n_rows:,} rows per scene")
    if d.method == "saltelli":
        return (f"n = {d.n} base samples of the saltelli design: {study.n_rows:,} rows per "
                "scene")
    return f"n = {d.n} samples per scene ({d.method})"


def _confirm_run(size, args: argparse.Namespace) -> bool:
    """Print a new run's size (samples, bytes, estimated time) before it starts; a large run
    needs --yes or a "y" at a terminal (refused without a terminal)."""
    if (not args.quiet and (size.seconds >= SIZE_LINE_SECONDS or size.bytes >= SIZE_LINE_BYTES)) \
            or size.large:
        print(f"skidmc run: {size.describe()}", file=sys.stderr)
    if not size.large or args.yes:
        return True
    if not (sys.stdin.isatty() and sys.stderr.isatty()):
        return False
    try:
        print("skidmc run: a large run; go on? [y/N] ", end="", file=sys.stderr, flush=True)
        answer = input()  # the prompt on stderr: stdout stays the result's
    except EOFError:
        return False
    return answer.strip().lower() in ("y", "yes")


def _warn_device_scenes(study) -> None:
    """With ``solver.backend = "cuda"``, name the study's scenes the device search cannot take
    (:func:`skidmc.solver.cuda.cpu_only_reason`): the run solves them with the CPU search on its
    one process's threads, no faster than ``backend = "cpu"``."""
    solver = getattr(study, "solver", None)
    if getattr(solver, "backend", "cpu") != "cuda" or not getattr(study, "scenes", None):
        return
    from skidmc.solver.cuda import cpu_only_reason

    cpu_only = [(s.name, why) for s in study.scenes
                if (why := cpu_only_reason(s.scene, float(solver.rtol))) is not None]
    if cpu_only:
        named = ", ".join(f"{name} ({why})" for name, why in cpu_only)
        print(f"skidmc run: warning: solver.backend = 'cuda', but {len(cpu_only)} of "
              f"{len(study.scenes)} scenes cannot run on the device: {named}. The device takes "
              "constant, homogeneous targets only; these scenes are solved by the CPU search on "
              "this process's threads, no faster than backend = 'cpu' (docs/gpu.md)",
              file=sys.stderr)


def _cmd_run(args: argparse.Namespace) -> int:
    """``skidmc run``: exit status 0 done (or up to date), 2 invalid study, option or result
    file, 130 interrupted. The kind of study is looked up (:mod:`skidmc.workflows`)."""
    from skidmc.ensemble.executors import default_workers
    from skidmc.ensemble.run import RunInterrupted
    from skidmc.workflows import RunOptions, check_options, get_kind, load

    parts = ["skidmc run", str(args.study)]
    for name in ("out", "n", "workers", "scheduler"):
        if getattr(args, name, None) is not None:
            parts.append(f"--{name} {getattr(args, name)}")
    parts += ["--resume"] * bool(args.resume) + ["--force"] * bool(args.force)
    cpus = default_workers()
    if args.workers is not None and args.workers > WORKERS_PER_CPU_WARNING * cpus:
        print(f"skidmc run: warning: --workers {args.workers} is far above the {cpus} CPUs "
              "available; running anyway, but the workers will share the CPUs (no faster than "
              f"--workers {cpus}) and each holds its own memory", file=sys.stderr)
    options = RunOptions(
        out=args.out, n=args.n, resume=args.resume, force=args.force, workers=args.workers,
        scheduler=args.scheduler, quiet=args.quiet, chunk_size=args.chunk_size,
        command=" ".join(parts), solver=args.solver, study_path=str(args.study),
        confirm=lambda size: _confirm_run(size, args), yes=args.yes)
    try:
        kind, study = load(args.study)
        check_options(kind, options)
        if not args.quiet:
            _warn_device_scenes(study)
        if getattr(study, "design", None) is not None and hasattr(study, "with_n"):
            shown = study.with_n(args.n) if args.n is not None else study  # StudyError: bad n
            if not args.quiet and (shown.design.n_epistemic
                                   or shown.design.method == "saltelli"):
                # n is not "samples per scene" there: say what it is
                print(f"skidmc run: {shown.file}: {_n_meaning(shown)}", file=sys.stderr)
        outcome = get_kind(kind).run(study, options)
    except SkidmcError as exc:  # StudyError, OptionError, StorageError, SchedulerError
        print(f"skidmc run: error: {exc}", file=sys.stderr)
        return 2
    except RunInterrupted as exc:
        print(f"skidmc run: interrupted; {exc.hint}", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print("skidmc run: interrupted", file=sys.stderr)
        return 130
    except OSError as exc:  # the file system said no somewhere storage did not expect it
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"skidmc run: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    return _finish(kind, outcome)


# --- skidmc report ------------------------------------------------------------------------------


def _add_report_parser(subparsers) -> None:
    report = subparsers.add_parser(
        "report", help="go-probability curves, log-normal fits, the experiments' verdict and "
        "Sobol indices of a study's results",
        description="Analyse a result file (or the result of a study file) and write figures, "
        "summary.md, summary.json and curves.h5 beside it.",
    )
    report.add_argument("target", help="result file (.h5) or study file (.toml)")
    report.add_argument("--out", help="folder for the report (default: the result file's)")
    report.add_argument("--confidence", type=_unit_interval,
                        help="coverage of every interval and band (default: 0.95)")
    report.set_defaults(func=_cmd_report)


def _unit_interval(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number in (0, 1), got {text!r}") from None
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"must be in (0, 1), got {text!r}")
    return value


def _check_out_folder(out: str) -> None:
    """Refuse a ``--out`` folder that cannot be made or written (a path through a file, under
    /proc or /sys, a device), before any work: :class:`SceneError` naming ``--out``."""
    import os
    from pathlib import Path

    folder = Path(out)
    if folder.exists() and not folder.is_dir():
        raise SceneError("--out", out, "is a file, not a folder: give a folder for the report")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SceneError("--out", out, f"cannot make this folder ({exc.strerror or exc}): "
                         "give a folder you can write") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise SceneError("--out", out, "is not writable: give a folder you can write")


def _cmd_report(args: argparse.Namespace) -> int:
    """``skidmc report``: exit status 0 written, 2 no usable result. The kind of study (of the
    study file, or of the study a result file stores) is looked up (:mod:`skidmc.workflows`)."""
    from pathlib import Path

    from skidmc.workflows import ReportOptions, check_options, get_kind, kind_of_result, load

    target = Path(args.target)
    if args.out is not None:
        _check_out_folder(args.out)
    options = ReportOptions(out=args.out, confidence=args.confidence, source=str(args.target))
    if target.suffix == ".toml":
        kind, subject = load(target)
    else:
        kind, subject = kind_of_result(target), target
    check_options(kind, options)
    return _finish(kind, get_kind(kind).report(subject, options))


# --- skidmc plan (issue 43) ----------------------------------------------------------------------


def _add_plan_parser(subparsers) -> None:
    """Register ``skidmc plan``: the next drop to make, from drops so far and a prior."""
    plan = subparsers.add_parser(
        "plan", help="the next go/no-go drop to make, with the current H50 and its interval",
        description="The drop height that minimises the expected posterior variance of ln H50 "
        "(or of ln q_p with --p) after its outcome (docs/planning.md). Drops from a report "
        "experiment (--experiment) or a CSV file with a column height_ft or height_m (or height "
        "with --units) and a column go (1/0) or outcome (E/N).",
    )
    plan.add_argument("drops", nargs="?", help="CSV file of the drops made so far")
    plan.add_argument("--experiment", metavar="NAME",
                      help="use the report's drops of this target (quartz, alumina_20_35, "
                      "alumina_50_80, gold)")
    plan.add_argument("--prior", choices=("physics", "vague"), default="physics",
                      help="physics: the model's prior predictive of the target (needs "
                      "--experiment or --target); vague: a decade at 1 sd around --guess "
                      "(default: physics where a target is known, else vague)")
    plan.add_argument("--target", metavar="NAME", help="target of the physics prior for a CSV")
    plan.add_argument("--discrepancy", type=float, default=0.0, metavar="SD",
                      help="model-discrepancy sd added to the physics prior's sd of ln H50 "
                      "(default: 0)")
    plan.add_argument("--guess", type=_positive_float, metavar="H",
                      help="centre of the vague prior [units] (default: the drops' geometric "
                      "mean)")
    plan.add_argument("--units", choices=("ft", "m"), default="ft", help="height unit")
    plan.add_argument("--p", type=_unit_interval, default=0.5,
                      help="plan for the height with P(go) = p (default: 0.5, H50)")
    plan.add_argument("--credibility", type=_unit_interval, default=0.9,
                      help="level of the printed interval (default: 0.9)")
    plan.add_argument("--json", action="store_true", help="print JSON")

    def _cmd_plan(args: argparse.Namespace) -> int:
        import csv
        from dataclasses import asdict

        import numpy as np

        from skidmc.analysis.experiments import get_experiment
        from skidmc.analysis.planning import next_drop
        from skidmc.analysis.posterior import physics_prior, vague_prior

        try:
            if (args.drops is None) == (args.experiment is None):
                raise ValueError("give either a CSV file of drops or --experiment NAME")
            target = args.experiment or args.target
            if args.experiment:
                drops = get_experiment(args.experiment, units=args.units).drops
                if drops is None:
                    raise ValueError(f"--experiment {args.experiment!r}: the report lists no "
                                     "drops for it")
                heights, went = drops.heights, drops.went
            else:
                with open(args.drops, newline="", encoding="utf-8") as f:
                    rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
                if not rows:
                    raise ValueError(f"{args.drops}: no drops")
                column = next((c for c in (f"height_{args.units}", "height") if c in rows[0]),
                              None)
                other = {"ft": "m", "m": "ft"}[args.units]
                factor = 1.0
                if column is None and f"height_{other}" in rows[0]:
                    column = f"height_{other}"
                    from skidmc.scene.units import FOOT

                    factor = FOOT if other == "ft" else 1 / FOOT
                if column is None:
                    raise ValueError(f"{args.drops}: needs a column height_ft, height_m or "
                                     f"height; has {', '.join(rows[0])}")
                heights = np.array([float(r[column]) * factor for r in rows])
                if "go" in rows[0]:
                    cells = [r["go"].strip() for r in rows]
                    bad = [c for c in cells if c not in ("0", "1")]
                    went = np.array([c == "1" for c in cells])
                elif "outcome" in rows[0]:
                    cells = [r["outcome"].strip().upper() for r in rows]
                    bad = [c for c in cells if c not in ("E", "N")]
                    went = np.array([c == "E" for c in cells])
                else:
                    raise ValueError(f"{args.drops}: needs a column go (1/0) or outcome (E/N)")
                if bad:
                    raise ValueError(f"{args.drops}: outcome {bad[0]!r} is not 1/0 or E/N")
            kind = args.prior if target else "vague"
            if kind == "physics":
                prior = physics_prior(target, units=args.units,
                                      discrepancy_sd=args.discrepancy)
            else:
                centre = args.guess or (float(np.exp(np.mean(np.log(heights))))
                                        if len(heights) else None)
                if centre is None:
                    raise ValueError("--guess H is needed for a vague prior without drops")
                prior = vague_prior(centre, units=args.units)
            result = next_drop(heights, went, prior, p=args.p, credibility=args.credibility,
                               units=args.units)
        except (ValueError, OSError) as err:
            print(f"skidmc plan: error: {err}", file=sys.stderr)
            return 2
        if args.json:
            print(_json({**asdict(result), "expected_gain": result.expected_gain}))
            return 0
        u = args.units
        name = "H50" if args.p == 0.5 else f"H{100 * args.p:g}"
        med, low, high = result.estimate
        print(f"drops so far: {result.n} ({result.n_go} go)")
        print(f"prior: {result.prior}")
        print(f"current {name}: {med:.3g} {u} ({args.credibility:.0%} interval {low:.3g} to "
              f"{high:.3g} {u})")
        print(f"next drop: {result.height:.3g} {u} (P(go) there {result.p_go:.2f})")
        print(f"expected gain: sd of ln {name} {result.sd_now:.3f} -> {result.sd_expected:.3f} "
              f"(variance -{result.expected_gain:.4f})")
        return 0

    plan.set_defaults(func=_cmd_plan)


# --- parser and entry point ----------------------------------------------------------------------


#: Options whose value may be a negative number (argparse takes "-1e-3" for an option and
#: says "expected one argument"): written as ``--opt=-1e-3`` before parsing, so that the
#: value reaches its check, which says what is wrong with it.
_NUMERIC_OPTIONS = ("--rtol", "--n", "--workers", "--confidence", "--discrepancy", "--guess",
                    "--p", "--credibility", "--h-min", "--h-max", "--chunk-size")


def _negative_numbers(argv: Sequence[str] | None) -> list[str]:
    argv = list(sys.argv[1:] if argv is None else argv)
    out: list[str] = []
    i = 0
    while i < len(argv):
        item = argv[i]
        if item in _NUMERIC_OPTIONS and i + 1 < len(argv) and _is_negative(argv[i + 1]):
            out.append(f"{item}={argv[i + 1]}")
            i += 2
            continue
        out.append(item)
        i += 1
    return out


def _is_negative(text: str) -> bool:
    if not text.startswith("-"):
        return False
    try:
        float(text.split()[0])
    except (ValueError, IndexError):
        return False
    return True


def build_parser() -> argparse.ArgumentParser:
    """The ``skidmc`` argument parser (subcommands ``presets``, ``materials``, ``height``,
    ``run``)."""
    parser = argparse.ArgumentParser(
        prog="skidmc", description="Oblique-impact (skid test) initiation model of HE billets."
    )
    parser.add_argument("--version", action="version", version=f"skidmc {__version__}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    presets = subparsers.add_parser(
        "presets", help="list the presets (the report's scenes) with their values and units"
    )
    presets.add_argument("name", nargs="?", help="show only this preset")
    presets.add_argument("--json", action="store_true", help="print JSON")
    presets.set_defaults(func=_cmd_presets)

    materials = subparsers.add_parser(
        "materials", help="list the target materials (for --set target=NAME) with sources",
        description="Named target materials: density, heat capacity and conductivity near room "
        "temperature, with their sources and spread.",
    )
    materials.add_argument("name", nargs="?", help="show only this material, with its source")
    materials.add_argument("--json", action="store_true", help="print JSON")
    materials.set_defaults(func=_cmd_materials)

    height = subparsers.add_parser(
        "height", help="critical drop height of one scene",
        description="Critical drop height of a scene: a preset with optional overrides.",
    )
    height.add_argument("--preset", required=True, metavar="NAME", help="preset to start from")
    height.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE",
        help="override a scene input; VALUE is SI or has units, e.g. flow_stress='34400 psi' "
        "(repeatable); target=MATERIAL sets the target's properties (skidmc materials)",
    )
    height.add_argument(
        "--rtol", type=_positive_float, default=1e-3,
        help="relative tolerance of the height search (default: %(default)g)",
    )
    height.add_argument(
        "--tier", choices=("full", "fast"), default="full", help="model tier (default: full)"
    )
    height.add_argument(
        "--h-min", metavar="H", help="lower search bound [m], or with units ('1 ft')"
    )
    height.add_argument("--h-max", metavar="H", help="upper search bound [m], or with units")
    height.add_argument("--json", action="store_true", help="print JSON")
    height.set_defaults(func=_cmd_height)

    _add_run_parser(subparsers)
    _add_report_parser(subparsers)
    _add_plan_parser(subparsers)
    return parser


def main(argv: Sequence[str] | None = None, *, solver=None) -> int:
    """Entry point of the ``skidmc`` console script.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments without the program name; ``sys.argv[1:]`` when None.
    solver : callable, optional
        Used instead of :func:`skidmc.solver.critical_height` by ``height`` and ``run`` (same
        signature; for ``run`` it must pickle, i.e. be a module-level function): for tests and
        for alternative solvers.

    Returns
    -------
    int
        Exit status: 0 success, 1 a missing component, 2 invalid input (one line on stderr).
        Usage errors exit with status 2 through :mod:`argparse` (``SystemExit``).
    """
    args = build_parser().parse_args(_negative_numbers(argv))
    args.solver = solver
    try:
        return args.func(args)
    except SkidmcError as err:
        print(f"skidmc: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("skidmc: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (`skidmc presets | head -1`): end quietly, as `cat` does; stdout
        # goes to /dev/null so that Python's flush at exit does not complain again.
        import os

        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, the status of a Unix tool stopped by a closed pipe
    except OSError as exc:  # the file system said no where no check expected it
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"skidmc: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
