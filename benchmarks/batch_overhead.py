"""Batch throughput on 2 workers against the in-process rate, and where the fixed cost goes.

A batch of study scenes (``benchmarks/study_scenes.py``: drawn from the shipped ensembles, with
temperature-dependent-target variants) is evaluated by :func:`skidmc.evaluate_batch` at one
rtol, in rounds, each round side by side on the same machine load:

* ``in process``: ``workers=1`` (the rate to beat: 2 workers should reach 2x it);
* ``2 workers, first pool of a process``: a fresh Python process (this script with ``--child``)
  draws the scenes, then times its first ``evaluate_batch(..., workers=2)``: the forkserver's
  start, the workers' start and the kernels' load from numba's cache are inside it, as for a
  ``skidmc run`` or a script's first batch; with ``--base SRC`` the same for another source
  tree (``git archive <commit> src | tar -x -C /tmp/base``), side by side;
* ``2 workers, new pool``: ``shutdown_workers()`` then a batch: a new pool from the forkserver
  this process already has (a second pool, or the replacement of a crashed one);
* ``2 workers, warm pool``: the pool ``evaluate_batch`` keeps between calls;
* ``2 threads, first batch of a process``: as the first pool, with ``scheduler="threads"``
  (:class:`skidmc.ensemble.executors.ThreadExecutor`): the fresh process loads the kernels
  itself, and no worker starts;
* ``2 threads``: ``scheduler="threads"`` in this process, kernels loaded.

Efficiency = rate on 2 workers / (2 x rate in process). Also: the solver's own time summed
over the batch (``BatchResult.wall_time``), so that "outside the solver" (start-up, scheduling,
pickling, idle tails) is 1 - solver time / (2 x wall); the time a fresh pool takes to be ready
(:class:`skidmc.ensemble.executors.ProcessExecutor`, both workers warmed up); and every result
is checked bitwise identical between the three.

Usage::

    python benchmarks/batch_overhead.py                      # 300 scenes, rtol 1e-3, 3 rounds
    python benchmarks/batch_overhead.py --base /tmp/base/src # and another tree's first pool
    python benchmarks/batch_overhead.py --rounds 1 --n 20    # quick

Writes ``results/benchmarks/batch_overhead.md`` (``--out``). The machine this runs on may be
shared: only ratios taken in one round mean much; the spread over rounds is given.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if "PYTHONPATH" not in os.environ:
    sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import study_scenes  # noqa: E402


def _cpu_of(pid):
    """CPU seconds (user + system) process `pid` has used so far (Linux /proc; nan elsewhere)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return float("nan")


def _workers_cpu():
    """{pid: CPU seconds} of the pool's worker processes and of their forkserver (what exists)."""
    from multiprocessing import forkserver

    from skidmc.ensemble import executors

    pool = executors.POOLS.get(2)
    pids = list(pool._pool._processes or {}) if pool is not None else []
    server = getattr(forkserver._forkserver, "_forkserver_pid", None)
    if server is not None:
        pids.append(server)
    return {pid: _cpu_of(pid) for pid in pids}


def pool_ready_seconds(workers=2):
    """Seconds from creating a pool to every worker warmed up (a fresh pool)."""
    from skidmc.ensemble import executors

    t0 = time.perf_counter()
    pool = executors.ProcessExecutor(workers)
    # Each worker's initializer has run once it answers; ask each of them (one task each, in
    # flight together, so that both must be up).
    futures = [pool._pool.submit(time.sleep, 0.2) for _ in range(workers)]
    for f in futures:
        f.result()
    seconds = time.perf_counter() - t0 - 0.2
    pool.shutdown()
    return seconds


def _measure(scenes, options, workers, scheduler=None):
    """(BatchResult, wall [s], CPU [s] of this process, the pool's workers and forkserver)."""
    import skidmc

    before = _workers_cpu()
    c0, t0 = time.process_time(), time.perf_counter()
    extra = {} if scheduler is None else {"scheduler": scheduler}
    res = skidmc.evaluate_batch(scenes, options, workers=workers, **extra)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    after = _workers_cpu()
    cpu += sum(v - before.get(pid, 0.0) for pid, v in after.items())
    return res, wall, cpu


def _digest(res):
    import hashlib

    text = repr([float(h).hex() for h in res.critical_height]) + repr(list(res.status))
    return hashlib.sha256((text + repr(list(res.flags))).encode()).hexdigest()


def _scenes(n, seed):
    return [scene for _, _, scene in study_scenes.draw(n // 3 + 1, seed)][:n]


def child(n, rtol, seed, scheduler=None):
    """A fresh process's first batch on 2 workers (forkserver and pool started by it), or on 2
    threads (``scheduler="threads"``: the kernels loaded by it)."""
    scenes = _scenes(n, seed)
    res, wall, cpu = _measure(scenes, {"rtol": rtol}, 2, scheduler)
    print(json.dumps({"wall": wall, "cpu": cpu, "solver": float(res.wall_time.sum()),
                      "digest": _digest(res)}))


def _first_pool(n, rtol, seed, src, scheduler=None):
    # Each tree its own numba cache (skidmc._numba_cache keys it by the tree's source): the
    # NUMBA_CACHE_DIR this process set would make the trees overwrite each other's kernels.
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = str(src)
    extra = [] if scheduler is None else ["--scheduler", scheduler]
    out = subprocess.run([sys.executable, __file__, "--child", "--n", str(n), "--rtol",
                          repr(rtol), "--seed", str(seed), *extra], env=env,
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def run(n, rtol, rounds, seed, base=None):
    import skidmc
    from skidmc.ensemble import executors

    scenes = _scenes(n, seed)
    options = {"rtol": rtol}
    skidmc.evaluate_batch(scenes[:4], options)            # load the kernels in this process
    here = Path(skidmc.__file__).resolve().parents[1]
    rows = []
    reference = {}   # per tree: the base tree's search is not this one's
    cases = ["in process", "2 workers, first pool of a process"]
    if base is not None:
        cases.append("2 workers, first pool of a process, base tree")
    cases += ["2 workers, new pool", "2 workers, warm pool",
              "2 threads, first batch of a process", "2 threads"]
    for r in range(rounds):
        for case in cases:
            workers = 1 if case == "in process" else 2
            scheduler = "threads" if case.startswith("2 threads") else None
            if "first" in case:
                got = _first_pool(n, rtol, seed, base if "base" in case else here, scheduler)
                wall, cpu, solver, digest = got["wall"], got["cpu"], got["solver"], got["digest"]
            else:
                if case == "2 workers, new pool":
                    executors.shutdown_workers()
                res, wall, cpu = _measure(scenes, options, workers, scheduler)
                solver, digest = float(res.wall_time.sum()), _digest(res)
            tree = "base" if "base" in case else "this"
            rows.append({"round": r + 1, "case": case, "wall": wall, "rate": n / wall,
                         "solver": solver, "workers": workers, "cpu": cpu, "tree": tree,
                         "same": digest == reference.setdefault(tree, digest)})
            print(rows[-1], flush=True)
    executors.shutdown_workers()
    ready = [pool_ready_seconds() for _ in range(rounds)]
    return scenes, rows, ready


def markdown(args, scenes, rows, ready, load_before, load_after):
    def by(case):
        return [x for x in rows if x["case"] == case]

    inproc = {x["round"]: x for x in by("in process")}
    lines = [
        "# Batch throughput on 2 workers against the in-process rate",
        "",
        f"Generated by `python benchmarks/batch_overhead.py --n {args.n} --rtol {args.rtol:g} "
        f"--rounds {args.rounds}`.",
        "",
        f"Machine: {os.cpu_count()} CPUs ({platform.machine()}), Python "
        f"{platform.python_version()}; load average {load_before} before, {load_after} after "
        "(the machine is shared: compare within a round).",
        "",
        f"Batch: {len(scenes)} scenes drawn from the shipped studies' ensembles "
        "(benchmarks/study_scenes.py: paper-series1, paper-series2, sobol-series1, with "
        "temperature-dependent-target variants), `evaluate_batch(scenes, {'rtol': "
        f"{args.rtol:g}}}, workers=w)` (the thread cases with `scheduler='threads'`). "
        "Efficiency = (rate on 2 workers) / (2 x rate in process "
        "in the same round). Outside solver = 1 - (summed solver time) / (workers x wall). CPU = "
        "CPU seconds of this process, of the pool's workers and of the forkserver that forks "
        "them during the batch (/proc); CPU efficiency = in-process CPU / that CPU: what the "
        "batch costs beyond the solver's own work, whatever other tenants take from the cores. "
        "Results identical bit for bit in every case of this tree: "
        f"{all(x['same'] for x in rows if x.get('tree') != 'base')}"
        + ("" if not any(x.get("tree") == "base" for x in rows) else
           "; in every case of the base tree (among themselves: its search is another): "
           f"{all(x['same'] for x in rows if x.get('tree') == 'base')}") + ".",
        "",
        "| round | case | wall [s] | heights/s | solver time [s] | outside solver [%] | "
        "efficiency vs 2x in process | CPU [s] | CPU efficiency |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for x in rows:
        base = inproc[x["round"]]
        eff = x["rate"] / (2 * base["rate"]) if x["workers"] == 2 else float("nan")
        outside = 100 * (1 - x["solver"] / (x["workers"] * x["wall"]))
        lines.append(f"| {x['round']} | {x['case']} | {x['wall']:.2f} | {x['rate']:.1f} | "
                     f"{x['solver']:.2f} | {outside:.1f} | "
                     + ("" if x["workers"] == 1 else f"{100 * eff:.0f} %")
                     + f" | {x['cpu']:.2f} | "
                     + ("" if x["workers"] == 1 else f"{100 * base['cpu'] / x['cpu']:.0f} %")
                     + " |")
    summary = []
    for case in dict.fromkeys(x["case"] for x in rows if x["workers"] == 2):
        effs = [x["rate"] / (2 * inproc[x["round"]]["rate"]) for x in by(case)]
        cpu = [inproc[x["round"]]["cpu"] / x["cpu"] for x in by(case)]
        pct = ", ".join(f"{100 * e:.0f} %" for e in effs)
        pct_cpu = ", ".join(f"{100 * e:.0f} %" for e in cpu)
        summary.append(f"- **{case}**: efficiency (wall) median "
                       f"{100 * statistics.median(effs):.0f} % (rounds: {pct}); CPU efficiency "
                       f"median {100 * statistics.median(cpu):.0f} % (rounds: {pct_cpu}).")
    lines += ["", *summary,
              f"- A fresh pool of 2 workers is ready (imports, kernels loaded by the warm-up "
              f"solve) after {statistics.median(ready):.2f} s (median of "
              f"{len(ready)}: {', '.join(f'{s:.2f}' for s in ready)} s).", ""]
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=300)
    parser.add_argument("--rtol", type=float, default=1e-3)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--seed", type=int, default=45)
    parser.add_argument("--base", help="the src folder of another tree: its first pool too")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--scheduler", help=argparse.SUPPRESS)
    parser.add_argument("--out", default=str(ROOT / "results" / "benchmarks" /
                                             "batch_overhead.md"))
    args = parser.parse_args(argv)
    if args.child:
        child(args.n, args.rtol, args.seed, args.scheduler)
        return 0
    load_before = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    scenes, rows, ready = run(args.n, args.rtol, args.rounds, args.seed, args.base)
    load_after = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    text = markdown(args, scenes, rows, ready, load_before, load_after)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
