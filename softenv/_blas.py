"""Which BLAS kernels numpy runs, for choices that depend on them (decode blocking, bench reports)."""

from __future__ import annotations

import ctypes
import functools

# OpenBLAS's AVX-512 kernel sets carry a "small matrix" GEMM that skips packing and writes C once; it
# takes products with M * N * K <= 100^3 (kernel/x86_64/*gemm_small_kernel_permit_skylakex.c)
SMALL_GEMM_KERNELS = ("SkylakeX", "Cooperlake", "SapphireRapids")
SMALL_GEMM_MAX_MNK = 1_000_000


@functools.cache
def openblas_kernels() -> str:
    """The kernel set numpy's OpenBLAS picked when it loaded ("Haswell", "SkylakeX", ...), or "unknown"
    (another BLAS, or no /proc). Fixed for the life of the process, so it is read once."""
    try:
        with open("/proc/self/maps") as fh:
            paths = {line.split()[-1] for line in fh if "openblas" in line.lower() and ".so" in line}
    except OSError:
        return "unknown"
    for path in sorted(paths, key=lambda p: "numpy" not in p):  # numpy's own copy first
        lib = ctypes.CDLL(path)  # already loaded: this only returns its handle
        for symbol in ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename", "openblas_get_corename64_",
                       "openblas_get_corename"):
            getter = getattr(lib, symbol, None)
            if getter is not None:
                getter.restype = ctypes.c_char_p
                return getter().decode()
    return "unknown"


def has_small_gemm() -> bool:
    """Whether numpy's BLAS has OpenBLAS's small-matrix GEMM path (see ``SMALL_GEMM_MAX_MNK``)."""
    return openblas_kernels() in SMALL_GEMM_KERNELS
