"""A sweep worker's private folder: a worker killed with SIGKILL leaves it, the next worker
of the same sweep removes it, a living worker's is kept, and nothing of another user or
outside the base is touched (issue 39)."""

from __future__ import annotations

import fcntl
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from orchestrator.sweep.tempdirs import WorkFolder, private_base, reap_dead

ROOT = Path(__file__).resolve().parents[1]
TAG = "0123456789ab"
#: a worker's set-up of its folder, then a life of work (killed by the test)
WORKER = """
import sys, time
from pathlib import Path
from orchestrator.sweep.tempdirs import WorkFolder
w = WorkFolder(sys.argv[1], Path(sys.argv[2]))
(w.path / "gait.json").write_text("{}")
print(w.path, flush=True)
time.sleep(120)
"""


#: the sweep's whole worker set-up (model, compiled closed loop, controllers) in its folder
RESOURCES = """
import sys, time
from pathlib import Path
from orchestrator.sweep.runs import Artifacts, Resources
from orchestrator.sweep.spec import load_spec
r = Resources(Artifacts.from_spec(load_spec("examples/sweep/quick.toml")), Path(sys.argv[2]))
print(r.workdir, flush=True)
time.sleep(120)
"""


def _worker(parent: Path, script: str = WORKER) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-c", script, TAG, str(parent)], cwd=ROOT,
                            env=env, stdout=subprocess.PIPE, text=True)


def _path(p: subprocess.Popen[str]) -> Path:
    assert p.stdout is not None
    line = p.stdout.readline().strip()
    assert line, f"worker exited with {p.wait()}"
    return Path(line)


def test_a_sigkilled_workers_folder_goes_at_the_next_start_a_living_ones_stays(tmp_path):
    live, dead = _worker(tmp_path), _worker(tmp_path)
    try:
        live_dir, dead_dir = _path(live), _path(dead)
        os.kill(dead.pid, signal.SIGKILL)
        assert dead.wait(10) == -signal.SIGKILL
        base = tmp_path / f"hpcosim-sweep-{TAG}"
        assert {live_dir.parent, dead_dir.parent} == {base}
        assert stat.S_IMODE(base.stat().st_mode) == 0o700
        assert stat.S_IMODE(live_dir.stat().st_mode) == 0o700
        assert (dead_dir / "gait.json").exists()  # SIGKILL left it
        outside = tmp_path / "outside"
        outside.mkdir()
        (outside / "keep.txt").write_text("x")
        (base / f"{dead.pid}-planted").symlink_to(outside)  # a dead PID's name, a link
        # the next worker of the sweep
        w = WorkFolder(TAG, tmp_path)
        try:
            assert not dead_dir.exists()
            assert (live_dir / "gait.json").exists()
            assert w.path.is_dir() and w.path.parent == base
            assert (outside / "keep.txt").read_text() == "x"  # the link was not followed
            assert (base / f"{dead.pid}-planted").is_symlink()
        finally:
            w.close()
        assert not w.path.exists()
        assert live.poll() is None
    finally:
        for p in (live, dead):
            p.kill()
            p.wait(10)


def test_a_reused_pid_does_not_keep_a_dead_workers_folder(tmp_path):
    # a living process started after the folder was last written cannot be its worker
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        base = private_base(tmp_path / "base")
        old, fresh = base / f"{other.pid}-old", base / f"{other.pid}-fresh"
        old.mkdir(mode=0o700)
        fresh.mkdir(mode=0o700)
        hour_ago = time.time() - 3600.0
        os.utime(old, (hour_ago, hour_ago))
        assert reap_dead(base) == [old]
        assert fresh.is_dir()  # written after that process started: it may be about to lock
    finally:
        other.kill()
        other.wait(10)


def test_a_locked_folder_is_kept_even_if_its_pid_is_dead(tmp_path):
    base = private_base(tmp_path / "base")
    held = base / "999999999-held"  # no such PID (above Linux's pid_max)
    held.mkdir(mode=0o700)
    fd = os.open(held, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_SH)  # e.g. a child of the dead worker still using it
        assert reap_dead(base) == []
        assert held.is_dir()
    finally:
        os.close(fd)
    assert reap_dead(base) == [held]


def test_the_base_folder_must_be_this_users_own_real_folder(tmp_path):
    target = tmp_path / "elsewhere"
    target.mkdir()
    (tmp_path / f"hpcosim-sweep-{TAG}").symlink_to(target)
    with pytest.raises(ValueError, match="not a folder of its own") as e:
        WorkFolder(TAG, tmp_path)
    assert "\n" not in str(e.value)
    assert list(target.iterdir()) == []
    (tmp_path / "open").mkdir(mode=0o777)
    os.chmod(tmp_path / "open", 0o777)
    assert stat.S_IMODE(private_base(tmp_path / "open").stat().st_mode) == 0o700


@pytest.mark.slow
def test_the_sweeps_own_worker_setup_killed_leaves_nothing_to_the_next_one(tmp_path):
    from orchestrator.sweep.runs import Artifacts, Resources
    from orchestrator.sweep.spec import load_spec

    p = _worker(tmp_path, RESOURCES)
    try:
        killed = _path(p)
        assert (killed / "gait.json").is_file() and (killed / "tube.json").is_file()
        os.kill(p.pid, signal.SIGKILL)
        assert p.wait(10) == -signal.SIGKILL
        assert killed.is_dir()
    finally:
        p.kill()
        p.wait(10)
    res = Resources(Artifacts.from_spec(load_spec(ROOT / "examples/sweep/quick.toml")),
                    tmp_path)
    try:
        assert not killed.exists() and res.workdir.parent == killed.parent
    finally:
        res.close()
    assert list(killed.parent.iterdir()) == []
