"""Compiled evaluation: generated C equals the CasADi graph it came from; the cache works;
the interpreter fallback gives the same numbers."""

from __future__ import annotations

import os

import casadi as ca
import numpy as np
import pytest

from hp_model.compiled import FunctionSet, NumericFunction
from tests.conftest import random_state


def test_compiled_c_equals_casadi_graph(model, rng):
    fs = model.numeric()
    assert fs.backend == "c", "a C compiler is part of this project's machines"
    for name in ("terms_ps", "dyn_pns", "impact_ps", "energy", "frames"):
        f = model.function(name)
        for _ in range(5):
            q, qd = random_state(model, rng)
            args = [q, qd] + ([rng.normal(size=model.nu)] if name.startswith("dyn") else [])
            ref = [np.array(o) for o in f(*args)]
            got = fs[name](*args)
            for r, g in zip(ref, got, strict=True):
                np.testing.assert_allclose(g.reshape(r.shape), r, rtol=1e-12,
                                           atol=1e-12 * max(1.0, np.abs(r).max()))


def test_cache_and_interpreter(tmp_path, monkeypatch):
    monkeypatch.setenv("HPCOSIM_CACHE", str(tmp_path))
    x = ca.SX.sym("x", 3)
    A = ca.SX.sym("A", 2, 3)
    f = ca.Function("f_test", [x, A], [A @ ca.sin(x), ca.sumsqr(x)])
    c1 = FunctionSet([f], "unit")
    libs = list((tmp_path / "casadi").glob("unit_*.so"))
    assert len(libs) == 1 and c1.library == libs[0]
    mtime = libs[0].stat().st_mtime_ns
    c2 = FunctionSet([f], "unit")  # cached: not rebuilt
    assert c2.library == libs[0] and libs[0].stat().st_mtime_ns == mtime
    sx = FunctionSet([f], "unit", backend="sx")
    xv, Av = np.array([0.1, -0.2, 0.3]), np.arange(6.0).reshape(2, 3)
    want = Av @ np.sin(xv)
    for fs in (c1, sx):
        y, s = fs["f_test"](xv, Av)
        np.testing.assert_allclose(y, want, rtol=1e-14)
        assert s[0] == pytest.approx(np.sum(xv**2))


def test_concurrent_builders_compile_a_library_once(tmp_path, monkeypatch):
    """Processes sharing a cache (parallel test workers, Dask workers) that want the same
    library at once: one compiles it, the others wait and load it; nothing half-written is
    ever in the cache."""
    import subprocess
    import threading

    import hp_model.compiled as compiled

    monkeypatch.setenv("HPCOSIM_CACHE", str(tmp_path))
    x = ca.SX.sym("x", 2)
    f = ca.Function("f_race", [x], [ca.cos(x)])
    calls: list[list[str]] = []
    real_run = subprocess.run

    def slow_compiler(cmd, **kw):
        calls.append(cmd)
        threading.Event().wait(0.3)  # the others arrive while this one compiles
        return real_run(cmd, **kw)

    monkeypatch.setattr(compiled.subprocess, "run", slow_compiler)
    got: list = []
    cwd = os.getcwd()
    threads = [threading.Thread(target=lambda: got.append(compiled.compile_library([f], "race")))
               for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    # the builders never touch the process's working directory (one per process: threads
    # that chdir'd each restored another's temporary, deleted, directory)
    assert os.getcwd() == cwd
    assert len(calls) == 1 and len(got) == 4 and len(set(got)) == 1
    assert [p.name for p in (tmp_path / "casadi").glob("race_*")] == [got[0].name]
    assert not [p for p in (tmp_path / "casadi").iterdir() if p.is_dir()]  # no temp left
    y = FunctionSet([f], "race")["f_race"](np.array([0.0, 1.0]))[0]
    np.testing.assert_allclose(y, np.cos([0.0, 1.0]), rtol=1e-15)


def test_numeric_function_rejects_wrong_arity():
    x = ca.SX.sym("x")
    nf = NumericFunction(ca.Function("g", [x], [x * 2]))
    with pytest.raises(TypeError, match="expected 1 inputs"):
        nf(1.0, 2.0)
