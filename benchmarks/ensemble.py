"""Ensemble throughput: samples per second for the shipped studies, and the runner's own costs.

Measures, on this machine:

1. For every study in ``studies/``: scene evaluations per second with 1 worker (in process) and
   with all CPUs (worker processes, their start-up included), and the share of the workers'
   wall time spent outside the solver,
   ``1 - sum(per-sample solver wall time) / (wall time x workers)`` (goal: <= 5 %), split by
   the run's per-chunk timeline into start-up, in-chunk overhead and idle time; and
   ``skidmc run`` of the first study end to end (a fresh process, as a user runs it).
2. Peak memory of a run against n, with the solver replaced by an instant stand-in so that large
   n are cheap: the runner must not hold all samples to write them, so the peak stays flat.

Writes ``results/benchmarks/ensemble.md`` and ``results/benchmarks/ensemble.csv``.

Usage::

    python benchmarks/ensemble.py                 # every shipped study at its own n
    python benchmarks/ensemble.py --n 64          # quicker
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from skidmc.ensemble.executors import default_workers  # noqa: E402 (after the sys.path set-up)
from skidmc.ensemble.hazard_study import is_hazard_study  # noqa: E402 (after the sys.path set-up)
from skidmc.ensemble.run import execute_study  # noqa: E402 (after the sys.path set-up)
from skidmc.ensemble.study import load_study  # noqa: E402 (after the sys.path set-up)

OUT = ROOT / "results" / "benchmarks"

# Peak memory of one run in a fresh process, solver stubbed out (see module docstring).
_MEMORY_PROBE = r"""
import json, resource, sys, types
sys.path.insert(0, sys.argv[1])
import skidmc.solver
def instant(scene, rtol=1e-3, tier="full", h_min=1e-3, h_max=1e4):
    return types.SimpleNamespace(critical_height=0.4 / scene.mu, censored=None, evaluations=1,
                                 flags=(), wall_time=0.0)
skidmc.solver.critical_height = instant
from skidmc.ensemble.run import execute_study
report = execute_study(sys.argv[2], sys.argv[3], n=int(sys.argv[4]), workers=1, progress=False)
print(json.dumps({"evaluated": report.evaluated, "wall": report.wall_time,
                  "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def _warm_up() -> None:
    """Compile (or load) the solver's kernels once, outside the timed runs."""
    from skidmc.scene import get_preset
    from skidmc.solver import critical_height

    critical_height(get_preset("paper-quartz"), rtol=1e-2)


def throughput(runs, worker_counts, tmp: Path) -> list[dict]:
    rows = []
    for path, n in runs:
        study = load_study(path)
        for workers in worker_counts:
            out = tmp / f"{study.name}-{n}-{workers}.h5"
            report = execute_study(study, out, n=n, workers=workers, progress=False,
                                   timeline=True)
            rows.append({
                "study": study.name, "design": study.design.method,
                "scenes": len(study.scenes), "samples_per_scene": report.n_rows,
                "workers": report.workers, "evaluations": report.evaluated,
                "wall_s": round(report.wall_time, 3), "solver_s": round(report.solver_time, 3),
                "evaluations_per_s": round(report.rate, 2),
                "outside_solver_pct": round(100 * report.outside_solver, 2),
                "failed": report.status_counts.get("failed", 0),
                **_breakdown(report),
            })
            print(rows[-1], flush=True)
    return rows


def _breakdown(report) -> dict:
    """Where the workers' time outside the solver went, in % of wall x workers.

    start-up: from the launch of the workers (or the first chunk, in process) to each worker's
    first chunk (worker start-up overlapped with the parent loading the study, opening the file
    and drawing the first chunk); in chunk: a chunk's time in its worker beyond the solver calls
    (building the scenes from the inputs); idle: between chunks and after a worker's last
    chunk (waiting for the parent, the tail of the run).
    """
    capacity = report.wall_time * report.workers
    by_worker: dict = {}
    for c in report.timeline:
        by_worker.setdefault(c["pid"], []).append(c)
    startup = in_chunk = 0.0
    for chunks in by_worker.values():
        startup += min(c["began_s"] for c in chunks)
        in_chunk += sum(c["ended_s"] - c["began_s"] - c["solver_s"] for c in chunks)
    startup += (report.workers - len(by_worker)) * report.wall_time  # a worker never used
    idle = capacity - report.solver_time - startup - in_chunk
    return {"chunks": report.chunks,
            "peak_worker_rss_mib": round(max(report.worker_peak_rss_mib.values(),
                                             default=float("nan")), 1),
            "startup_pct": round(100 * startup / capacity, 2),
            "in_chunk_pct": round(100 * in_chunk / capacity, 2),
            "idle_pct": round(100 * idle / capacity, 2)}


def command_line(path: Path, n: int | None, workers: int, tmp: Path) -> dict:
    """`skidmc run` end to end, as a user runs it: process start to exit."""
    import time

    out = tmp / f"cli-{workers}.h5"
    cmd = [sys.executable, "-m", "skidmc.cli", "run", str(path), "--out", str(out),
           "--workers", str(workers)] + (["--n", str(n)] if n else [])
    t = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True, check=True)
    wall = time.perf_counter() - t
    summary = [line for line in res.stderr.splitlines() if "evaluations in" in line]
    row = {"command": " ".join(["skidmc run", path.relative_to(ROOT).as_posix(),
                                f"--workers {workers}"] + ([f"--n {n}"] if n else [])),
           "end_to_end_s": round(wall, 2),
           "summary": summary[-1].split(": ", 1)[-1] if summary else ""}
    print(row, flush=True)
    return row


def memory(study_path: Path, ns, tmp: Path) -> list[dict]:
    rows = []
    for n in ns:
        out = tmp / f"memory-{n}.h5"
        res = subprocess.run([sys.executable, "-c", _MEMORY_PROBE, str(ROOT / "src"),
                              str(study_path), str(out), str(n)],
                             capture_output=True, text=True, check=True)
        probe = json.loads(res.stdout.strip().splitlines()[-1])
        rows.append({"study": load_study(study_path).name, "samples_per_scene": n,
                     "evaluations": probe["evaluated"],
                     "peak_rss_mib": round(probe["peak_rss_mib"], 1),
                     "file_mib": round(out.stat().st_size / 2**20, 2)})
        print(rows[-1], flush=True)
    return rows


def write(rows: list[dict], mem: list[dict], load: tuple[float, ...],
          cli: list[dict]) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    with open(OUT / "ensemble.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    cpu = platform.processor() or platform.machine()
    lines = [
        "# Ensemble throughput (benchmarks/ensemble.py)",
        "",
        (f"Machine: {os.cpu_count()} CPUs ({cpu}), Python {platform.python_version()}, "
         f"{platform.system()}. An evaluation is one scene at one sample (one critical-height "
         "search at the study's rtol). With several workers, the wall time runs from the launch "
         "of the worker processes, which `execute_study` does first so that their start-up "
         "(forked from a forkserver that imports numpy, numba, scipy and skidmc once; then "
         "each loads the compiled kernels from numba's cache) overlaps the parent loading the "
         "study and opening the file, to the last chunk written; in process (1 worker) it "
         "runs from the first chunk. It covers sampling, scene building, solver and writing."),
        "",
        (f"Load average before the runs (1, 5, 15 min): {load[0]:.2f}, {load[1]:.2f}, "
         f"{load[2]:.2f}; the machine is shared: other work slows the solver itself, which the "
         "outside-solver share does not see but the evaluations/s do."),
        "",
        ("outside solver = 1 - sum(per-sample solver wall time) / (wall time x workers): the "
         "share of the workers' time not spent in `critical_height` (goal <= 5 %). It splits "
         "into start-up (launch to each worker's first chunk: the workers' start and the "
         "parent's preparation, overlapped), in chunk (a chunk's time in its worker beyond the "
         "solver calls: building each sample's scene from its inputs, `SceneColumns` over the "
         "study's base scene) and idle (between "
         "chunks and after a worker's last one: waiting for the parent, the run's tail)."),
        "",
        ("| study | design | scenes | samples/scene | workers | evaluations | chunks | wall [s] "
         "| evaluations/s | outside solver [%] | start-up [%] | in chunk [%] | idle [%] "
         "| peak RSS per worker [MiB] | failed |"),
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['study']} | {r['design']} | {r['scenes']} | {r['samples_per_scene']} "
                     f"| {r['workers']} | {r['evaluations']} | {r['chunks']} | {r['wall_s']:.1f} "
                     f"| {r['evaluations_per_s']:.1f} | {r['outside_solver_pct']:.1f} "
                     f"| {r['startup_pct']:.1f} | {r['in_chunk_pct']:.1f} | {r['idle_pct']:.1f} "
                     f"| {r['peak_worker_rss_mib']} | {r['failed']} |")
    if cli:
        lines += [
            "",
            "## The command, end to end",
            "",
            ("The whole command as a user runs it, from process start to exit (imports, study, "
             "file, workers, evaluation), with the summary line it prints."),
            "",
            "| command | end to end [s] | summary |",
            "|---|---|---|",
        ]
        for r in cli:
            lines.append(f"| `{r['command']}` | {r['end_to_end_s']:.1f} | {r['summary']} |")
    lines += [
        "",
        "## Peak memory against n",
        "",
        ("Solver replaced by an instant stand-in, 1 worker, a fresh process per n: the runner's "
         "and the storage's own memory. Results go to disk chunk by chunk, so the peak should "
         "not grow with n (the lhs design itself, n x d floats, is the only O(n) array). The "
         "worker processes' own peak is in the table above and, against the evaluations a "
         "worker has done, in throughput.md."),
        "",
        "| study | samples/scene | evaluations | peak RSS [MiB] | file [MiB] |",
        "|---|---|---|---|---|",
    ]
    for r in mem:
        lines.append(f"| {r['study']} | {r['samples_per_scene']} | {r['evaluations']} "
                     f"| {r['peak_rss_mib']} | {r['file_mib']} |")
    (OUT / "ensemble.md").write_text("\n".join(lines) + "\n")
    with open(OUT / "ensemble_memory.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(mem[0]))
        writer.writeheader()
        writer.writerows(mem)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, help="samples per scene (default: each study's)")
    parser.add_argument("--long-n", type=int, default=1024,
                        help="samples per scene of one longer run of the first study, where "
                        "the workers' start-up weighs less (0: skip)")
    parser.add_argument("--memory-n", type=int, nargs="+", default=[1000, 4000, 16000],
                        help="sample counts of the memory probe")
    args = parser.parse_args(argv)
    studies = sorted(p for p in (ROOT / "studies").glob("*.toml")
                     if not is_hazard_study(p))  # hazard studies are benchmarks/hazard.py's
    worker_counts = sorted({1, default_workers()})
    _warm_up()
    load = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        runs = [(path, args.n) for path in studies]
        if args.long_n:
            runs.append((studies[0], args.long_n))
        rows = throughput(runs, worker_counts, Path(tmp))
        cli = [command_line(studies[0], args.n, w, Path(tmp)) for w in worker_counts[::-1]]
        mem = memory(ROOT / "studies" / "paper-series1.toml", args.memory_n, Path(tmp))
    write(rows, mem, load, cli)
    print(f"wrote {OUT / 'ensemble.md'}")


if __name__ == "__main__":
    main()
