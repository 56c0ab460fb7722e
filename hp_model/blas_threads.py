"""One thread for the linear algebra of every numerical solve, whatever the environment.

OpenBLAS splits a product over its threads and sums the parts in an order that depends on
their number, so the same IPOPT/MUMPS solve takes other pivots and other steps with 1 or 2
threads (measured: the PHZD template gait took 82 iterations with the default threads and
300 with ``OPENBLAS_NUM_THREADS=1``, ending at different gaits).  The thread count comes from
``OPENBLAS_NUM_THREADS``/``OMP_NUM_THREADS`` and the CPU count, so a result would depend on
the user's shell and machine.  :func:`single_threaded_blas` pins every BLAS and OpenMP pool
loaded in the process to one thread for the duration of a solve, through threadpoolctl;
CasADi's wheel ships its own OpenBLAS (``libcasadi-tp-openblas``), which threadpoolctl does
not know by name, so a controller for it is registered here.

Results are then identical whatever the thread settings or the load.  Bit-identity across
CPU models is not promised: OpenBLAS and libm pick kernels by instruction set.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import threadpoolctl


class CasadiOpenBLASController(threadpoolctl.OpenBLASController):
    """threadpoolctl's OpenBLAS controller for the copy inside the casadi wheel."""

    filename_prefixes = ("libcasadi-tp-openblas",)


threadpoolctl.register(CasadiOpenBLASController)


def load_casadi_blas() -> None:
    """Load CasADi's IPOPT plugin (and with it its OpenBLAS), so that a limit set now
    reaches it; CasADi otherwise loads it only when the first IPOPT solver is made."""
    import casadi as ca

    loaded = any(i["filepath"].rsplit("/", 1)[-1].startswith("libcasadi-tp-openblas")
                 for i in threadpoolctl.threadpool_info())
    if not loaded:
        ca.load_nlpsol("ipopt")


@contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Every BLAS and OpenMP pool in the process at one thread inside the block."""
    load_casadi_blas()
    with threadpoolctl.threadpool_limits(limits=1):
        yield


def blas_thread_counts() -> dict[str, int]:
    """Thread count of each BLAS/OpenMP library loaded now, by file name (diagnostics)."""
    return {i["filepath"].rsplit("/", 1)[-1]: int(i["num_threads"])
            for i in threadpoolctl.threadpool_info()}
