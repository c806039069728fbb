"""Compile the GPU kernel of :mod:`skidmc.solver.cuda` to PTX without a GPU.

A check that the device search (:mod:`skidmc.solver.device` and the kernels it calls) compiles
for a real CUDA target, not only under numba's simulator. It needs the ``numba-cuda`` package
and NVIDIA's NVVM and NVRTC libraries (a CUDA toolkit, or ``pip install numba-cuda
nvidia-cuda-nvrtc``), but no GPU or driver: numba-cuda asks the driver for the compute
capability of the current device when it compiles a device function, so this script answers
for it (``--cc``, default 9.0, the H100/H200).

    CUDA_HOME=/usr/local/cuda python scripts/compile_cuda_ptx.py [--cc 9.0] [--out kernel.ptx]

Prints the size of the PTX and the registers and local memory the kernel asks for, if the PTX
says.
"""

from __future__ import annotations

import argparse
import re
import sys
import types


def compile_ptx(cc=(9, 0)):
    """PTX of the kernel for compute capability ``cc`` (str)."""
    import numba.cuda.dispatcher as dispatcher

    from skidmc.solver import cuda as backend

    # No driver: tell the device-function compiler which target to build for.
    dispatcher.get_current_device = lambda: types.SimpleNamespace(compute_capability=cc)
    numba_cuda = backend._numba_cuda()
    ptx, _ = numba_cuda.compile_ptx(backend._thread, backend.THREAD_SIGNATURE, cc=cc)
    return ptx


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cc", default="9.0", help="compute capability (default 9.0)")
    parser.add_argument("--out", help="write the PTX here")
    args = parser.parse_args(argv)
    cc = tuple(int(v) for v in args.cc.split("."))
    ptx = compile_ptx(cc)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(ptx)
    local = re.findall(r"\.local \.align \d+ \.b8\s+\S+\[(\d+)\]", ptx)
    print(f"PTX for sm_{cc[0]}{cc[1]}: {len(ptx):,} characters, "
          f"{len(ptx.splitlines()):,} lines; local memory per thread "
          f"{sum(int(v) for v in local):,} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
