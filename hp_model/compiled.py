"""Fast numeric evaluation of CasADi functions: generated C, compiled once, called through
preallocated buffers.

Calling a CasADi Function the default way costs about 28 us of numpy-to-DM conversion
(REFERENCE.md Sec. 3).  Here a set of SX Functions is generated as one C file, compiled with
the system C compiler into a shared library cached by the hash of its source, loaded with
``casadi.external`` and bound to numpy arrays with ``Function.buffer()``.  Without a C
compiler the SX Functions are bound the same way (slower: the SX interpreter).

:class:`NumericFunction` owns its input and output arrays, like Pinocchio's ``Data``: the
arrays it returns are overwritten by its next call; copy them to keep them.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from pathlib import Path

import casadi as ca
import numpy as np

from hp_model.choices import Choice

CFLAGS = ("-O2", "-fPIC", "-shared", "-fno-math-errno")


class CompileError(RuntimeError):
    """The C compiler failed on generated code."""


class CompileBackend(Choice):
    """How a :class:`FunctionSet` evaluates its functions."""

    AUTO = "auto"  # C when a compiler is found, else SX
    C = "c"  # generated C, compiled (raise if impossible)
    SX = "sx"  # the CasADi SX interpreter


def cache_root() -> Path:
    """hpcosim's cache (compiled models, built FMUs): $HPCOSIM_CACHE, else ~/.cache/hpcosim."""
    env = os.environ.get("HPCOSIM_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "hpcosim"


def cache_dir() -> Path:
    """Where compiled libraries are kept: ``cache_root()/casadi``."""
    return cache_root() / "casadi"


def find_c_compiler() -> str | None:
    """$CC if set, else cc/gcc/clang on PATH."""
    for cand in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if cand and shutil.which(cand):
            return cand
    return None


def generate_c(functions: Sequence[ca.Function], name: str) -> str:
    """C source of the functions, as one translation unit."""
    with tempfile.TemporaryDirectory() as tmp:
        cg = ca.CodeGenerator(f"{name}.c", {"with_header": False})
        for f in functions:
            cg.add(f)
        # into the directory given as the prefix: never chdir, the process's one working
        # directory (threads building at once would each restore another's, deleted, one)
        return Path(cg.generate(tmp + os.sep)).read_text()


def compile_library(functions: Sequence[ca.Function], name: str) -> Path:
    """Generate, compile (cached by source hash) and return the shared library path."""
    cc = find_c_compiler()
    if cc is None:
        raise CompileError("no C compiler found (set CC or install gcc)")
    src = generate_c(functions, name)
    key = hashlib.sha256((src + " ".join(CFLAGS) + cc).encode()).hexdigest()[:20]
    out_dir = cache_dir()
    so = out_dir / f"{name}_{key}.so"
    if so.exists():
        return so
    out_dir.mkdir(parents=True, exist_ok=True)
    # one builder per library: processes sharing the cache (parallel test workers, Dask
    # workers) that want the same library wait for the first one's build instead of
    # compiling it again; the rename keeps a half-written library from ever being seen
    with open(out_dir / f".{so.name}.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if so.exists():
            return so
        with tempfile.TemporaryDirectory(dir=out_dir) as tmp:
            c_path = Path(tmp) / f"{name}.c"
            c_path.write_text(src)
            tmp_so = Path(tmp) / f"{name}.so"
            proc = subprocess.run(
                [cc, *CFLAGS, str(c_path), "-o", str(tmp_so), "-lm"],
                capture_output=True, text=True,
            )
            if proc.returncode != 0:
                first = (proc.stderr.strip().splitlines() or ["unknown error"])[0]
                raise CompileError(f"compiling {name}.c failed: {first}")
            os.replace(tmp_so, so)  # atomic: a reader never sees a partial library
    return so


class NumericFunction:
    """A CasADi Function bound to preallocated numpy buffers.

    Inputs are copied into owned arrays (``self.inputs``); outputs are owned arrays
    (``self.outputs``, dense, 1-D for vectors and Fortran-ordered 2-D for matrices) that the
    call returns and the next call overwrites.
    """

    def __init__(self, f: ca.Function) -> None:
        self.function = f
        self.name = f.name()
        self.inputs: list[np.ndarray] = []
        self.outputs: list[np.ndarray] = []
        self._buf, self._trigger = f.buffer()
        for i in range(f.n_in()):
            if f.sparsity_in(i).nnz() != f.numel_in(i):
                raise ValueError(f"{self.name}: input {i} must be dense")
            arr = np.zeros(f.numel_in(i))
            self.inputs.append(arr)
            # the stubs list the byte size the SWIG wrapper takes from the buffer itself
            self._buf.set_arg(i, arr.data)  # type: ignore[call-arg]  # casadi stubs
        for i in range(f.n_out()):
            if f.sparsity_out(i).nnz() != f.numel_out(i):
                raise ValueError(f"{self.name}: output {i} must be dense")
            n, m = f.size_out(i)
            flat = np.zeros(n * m)
            self._buf.set_res(i, flat.data)  # type: ignore[call-arg]  # casadi stubs
            self.outputs.append(flat if m == 1 else flat.reshape((n, m), order="F"))
        self._n_in = f.n_in()
        #: the bound evaluation itself (what :meth:`call_inplace` calls), for hot loops
        self.trigger = self._trigger

    def __call__(self, *args: np.ndarray | Sequence[float] | float) -> tuple[np.ndarray, ...]:
        if len(args) != self._n_in:
            raise TypeError(f"{self.name}: expected {self._n_in} inputs, got {len(args)}")
        for dst, a in zip(self.inputs, args, strict=True):
            if isinstance(a, np.ndarray) and a.ndim == 2:
                a = a.ravel(order="F")
            dst[:] = a
        self._trigger()
        return tuple(self.outputs)

    def call_inplace(self) -> None:
        """Evaluate with whatever is in ``self.inputs`` (fastest path)."""
        self._trigger()


def densified(f: ca.Function) -> ca.Function:
    """The same function with every output dense (structural zeros stored)."""
    if all(f.sparsity_out(i).is_dense() for i in range(f.n_out())) and all(
        f.sparsity_in(i).is_dense() for i in range(f.n_in())
    ):
        return f
    args = [ca.SX.sym(f.name_in(i), f.size_in(i)) for i in range(f.n_in())]
    outs = f.call(args)
    return ca.Function(f.name(), args, [ca.densify(o) for o in outs],
                       f.name_in(), f.name_out())


class FunctionSet:
    """Named CasADi Functions evaluated as compiled C (or the SX interpreter as fallback).

    ``backend``: a :class:`CompileBackend` or its value; ``self.backend`` is the one used
    (``C`` or ``SX``, never ``AUTO``).
    """

    def __init__(self, functions: Sequence[ca.Function], name: str,
                 backend: CompileBackend | str = CompileBackend.AUTO) -> None:
        functions = [densified(f) for f in functions]
        self.symbolic = {f.name(): f for f in functions}
        backend = CompileBackend(backend)
        if backend == CompileBackend.AUTO:
            backend = CompileBackend.C if find_c_compiler() else CompileBackend.SX
        self.backend = backend
        self.library: Path | None = None
        if backend == CompileBackend.C:
            self.library = compile_library(list(functions), name)
            self._numeric = {
                n: NumericFunction(ca.external(n, str(self.library))) for n in self.symbolic
            }
        else:
            self._numeric = {n: NumericFunction(f) for n, f in self.symbolic.items()}

    def __getitem__(self, name: str) -> NumericFunction:
        try:
            return self._numeric[name]
        except KeyError:
            raise KeyError(f"no function '{name}'; have {sorted(self._numeric)}") from None

    def __contains__(self, name: str) -> bool:
        return name in self._numeric
