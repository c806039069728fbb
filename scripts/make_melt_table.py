"""Write ``src/skidmc/data/melt_table.txt``: the fast tier's melting depression G(r) table.

:data:`skidmc.physics.fast.MELT_TABLE` is read from that file instead of being computed at
every import (scipy.special and ~0.1 s of Newton iterations). This script computes it with
:func:`skidmc.physics.fast.melt_table` and writes each value as ``float.hex`` (exact), so that
the stored table is the computed one bit for bit; ``tests/test_fast.py`` recomputes it.

Usage::

    python scripts/make_melt_table.py           # write the file
    python scripts/make_melt_table.py --check   # exit 1 if the file differs from a recomputation
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from skidmc.physics.fast import MELT_TABLE_FILE, melt_table  # noqa: E402

HEADER = ("# G(r), the fast tier's melting depression (skidmc.physics.fast.melt_depression), on\n"
          "# r = i / 200, i = 0..200 (G(0) from r = 1e-3), as float.hex; written by\n"
          "# scripts/make_melt_table.py from skidmc.physics.fast.melt_table().\n")


def text():
    return HEADER + "".join(f"{float(v).hex()}\n" for v in melt_table())


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true")
    args = parser.parse_args(argv)
    new = text()
    if args.check:
        same = MELT_TABLE_FILE.read_text() == new
        print(f"{MELT_TABLE_FILE}: {'identical to' if same else 'DIFFERS from'} a recomputation")
        return 0 if same else 1
    MELT_TABLE_FILE.write_text(new)
    print(f"wrote {MELT_TABLE_FILE}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
