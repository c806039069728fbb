"""Every critical height of a set of scenes, bit for bit: run before and after a change, compare.

The scenes: the report's presets (and their temperature-dependent-target variants) and a draw
from the shipped studies' ensembles (``benchmarks/study_scenes.py``), at rtol 1e-2, 3e-3 and
1e-3. For each: the CPU search's result (:func:`skidmc.critical_height`: height, censoring,
error estimate, evaluations, flags, or the failure's text) and the device search's output row on
the CPU's threads (``skidmc.solver.cuda.critical_heights(..., backend="cpu")``, the function a
GPU thread runs) for the scenes it takes (constant, homogeneous targets).

The script uses the package on ``sys.path`` (it does not add this checkout's ``src``), so the
same file fingerprints another source tree::

    git archive <commit> src | tar -x -C /tmp/base
    PYTHONPATH=/tmp/base/src python benchmarks/heights_fingerprint.py --out /tmp/before.json
    PYTHONPATH=$PWD/src python benchmarks/heights_fingerprint.py --out /tmp/after.json
    python benchmarks/heights_fingerprint.py --compare /tmp/before.json /tmp/after.json

Floats are written as ``float.hex`` strings: equal text is equal bits.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import study_scenes  # noqa: E402

RTOLS = (1e-2, 3e-3, 1e-3)


def _hex(x):
    return float(x).hex()


def fingerprint(n_per_study, seed):
    import numpy as np

    import skidmc
    from skidmc.scene import NUMERIC_KEYS

    scenes = study_scenes.presets() + study_scenes.draw(n_per_study, seed)
    out = {"package": skidmc.__file__, "scenes": [label for label, _, _ in scenes], "cpu": {},
           "device": {}}
    for rtol in RTOLS:
        rows = []
        for _label, _group, scene in scenes:
            try:
                res = skidmc.critical_height(scene, rtol=rtol)
                rows.append([_hex(res.critical_height), str(res.censored),
                             _hex(res.error_estimate), int(res.evaluations), list(res.flags)])
            except Exception as exc:  # noqa: BLE001 - a failure is part of the fingerprint
                rows.append([f"{type(exc).__name__}: {exc}"])
        out["cpu"][repr(rtol)] = rows
        try:
            from skidmc.solver.cuda import critical_heights
        except ImportError:
            continue
        take = [i for i, (_l, _g, s) in enumerate(scenes)
                if not s.target_table and not s.target_layers]
        values = np.array([[scenes[i][2].as_dict()[k] for k in NUMERIC_KEYS] for i in take])
        dev, _seconds = critical_heights(values, rtol, backend="cpu")
        out["device"][repr(rtol)] = {scenes[i][0]: [_hex(v) for v in dev[j]]
                                     for j, i in enumerate(take)}
    return out


def compare(a_path, b_path):
    a, b = (json.loads(Path(p).read_text()) for p in (a_path, b_path))
    if a["scenes"] != b["scenes"]:
        print("different scene lists")
        return 2
    differ = 0
    for rtol, rows in a["cpu"].items():
        other = b["cpu"][rtol]
        bad = [label for label, x, y in zip(a["scenes"], rows, other) if x != y]
        differ += len(bad)
        print(f"cpu rtol {rtol}: {len(rows) - len(bad)}/{len(rows)} identical"
              + (f"; differ: {bad}" if bad else ""))
    for rtol, rows in a["device"].items():
        other = b["device"].get(rtol, {})
        bad = [label for label, x in rows.items() if other.get(label) != x]
        print(f"device rtol {rtol}: {len(rows) - len(bad)}/{len(rows)} identical"
              + (f"; differ: {bad}" if bad else ""))
    return 1 if differ else 0


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", help="write the fingerprint here (JSON)")
    parser.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"))
    parser.add_argument("--n", type=int, default=60, help="samples per study (default 60)")
    parser.add_argument("--seed", type=int, default=45)
    args = parser.parse_args(argv)
    if args.compare:
        return compare(*args.compare)
    t0 = time.perf_counter()
    result = fingerprint(args.n, args.seed)
    Path(args.out).write_text(json.dumps(result) + "\n")
    print(f"{len(result['scenes'])} scenes x {len(RTOLS)} rtol from {result['package']} in "
          f"{time.perf_counter() - t0:.1f} s -> {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
