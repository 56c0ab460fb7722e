"""A write that fails (a full disk, a file-size limit) leaves nothing under the target name
nor a temporary file, and names the file the user asked for."""

from __future__ import annotations

import errno
import sys
import textwrap
from pathlib import Path

from tests.full_disk import run_with_file_limit

ROOT = Path(__file__).resolve().parents[1]


def _py(code: str, limit: int, tmp: Path):
    return run_with_file_limit([sys.executable, "-c", textwrap.dedent(code)], limit,
                               cwd=str(ROOT), env={"PYTHONPATH": str(ROOT), "TMP": str(tmp),
                                                   "PATH": "/usr/bin:/bin"})


def test_atomic_write_on_a_full_disk_leaves_nothing(tmp_path):
    out = tmp_path / "gait.json"
    r = _py(f"""
        import sys
        from hp_model.atomic_io import atomic_write_bytes
        try:
            atomic_write_bytes({str(out)!r}, b"x" * 200_000)
        except OSError as e:
            print(e.errno, e.filename, sep="|")
        """, 65536, tmp_path)
    code, name = r.stdout.strip().split("|")
    assert int(code) == errno.EFBIG and name == str(out), r
    assert list(tmp_path.iterdir()) == []  # neither the target nor a temporary file


def test_recording_on_a_full_disk_leaves_nothing(tmp_path):
    out = tmp_path / "run.mcap"
    r = _py(f"""
        import os
        from bus_schemas.recording.recorder import Recorder
        try:
            with Recorder({str(out)!r}, compression="none", chunk_size=4096) as rec:
                rec.register_all()
                for k in range(100_000):
                    rec.write("/controller/disturbance", {{"t": k * 1e-3, "d": [0.0, 0.0],
                              "tau": 0.5, "valid": True, "flag": False,
                              "since_touchdown": 0.1}}, k * 1_000_000)
        except OSError as e:
            print(e.errno, e.filename, rec.write_failed, sep="|")
        """, 65536, tmp_path)
    assert r.stdout.strip() == f"{errno.EFBIG}|{out}|True", r
    assert list(tmp_path.iterdir()) == []  # no run.mcap, no .run.mcap.part
