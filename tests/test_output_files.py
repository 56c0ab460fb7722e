"""Output files are created safely in any folder and with the user's umask; nothing a run
keeps private (the run's secret, the extracted FMU) outlives a run killed with SIGKILL.

Atomic writes (hp_model.atomic_io) and the recording's ``.part`` file never follow a link
or write into a file planted by someone else; the final files get 0o666 less the umask.
"""

from __future__ import annotations

import contextlib
import os
import signal
import stat
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from bus_schemas.recording.part_file import RecordingInUseError, UnsafePartFileError
from bus_schemas.recording.reader import read_messages
from bus_schemas.recording.recorder import Recorder
from hp_model.atomic_io import atomic_write_bytes, atomic_write_text, atomic_write_with
from tests.fmu_support import built_fmu

ROOT = Path(__file__).resolve().parents[1]
NOBODY = 65534
PRECIOUS = b"root-only data that must never change\n"


@contextlib.contextmanager
def umask(mask: int):
    old = os.umask(mask)
    try:
        yield
    finally:
        os.umask(old)


def mode(p: Path) -> int:
    return stat.S_IMODE(os.lstat(p).st_mode)


def victim(tmp_path: Path) -> Path:
    """A root-only file outside the output, which nothing may change."""
    v = tmp_path / "elsewhere" / "shadow"
    v.parent.mkdir()
    v.write_bytes(PRECIOUS)
    v.chmod(0o600)
    return v


def shared_folder(tmp_path: Path) -> Path:
    """A world-writable sticky folder, as /tmp or a lab's shared drive."""
    d = tmp_path / "shared"
    d.mkdir()
    d.chmod(0o1777)
    return d


def record(path: Path, n: int = 50) -> None:
    with Recorder(path) as rec:
        rec.register_all()
        for k in range(n):
            rec.write("/controller/disturbance", {"t": k * 1e-3, "d": [0.0, 0.0], "tau": 0.5,
                                                  "valid": True, "flag": False,
                                                  "since_touchdown": 0.1}, k * 1_000_000)


def recorded_times(path: Path) -> list[float]:
    return [o["t"] for _, _, o in read_messages(path, ["/controller/disturbance"])]


# ----------------------------------------------------------------------- umask of outputs


@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002])
def test_atomic_writes_get_the_umask(tmp_path, mask):
    """Every atomic writer gives 0o666 less the umask (mkstemp's 0600 before the fix)."""
    want = 0o666 & ~mask
    with umask(mask):
        atomic_write_bytes(tmp_path / "a.bin", b"x")
        atomic_write_text(tmp_path / "b.txt", "x")
        atomic_write_with(tmp_path / "c.npz", lambda t: Path(t).write_bytes(b"x"),
                          suffix=".npz")
        from hp_model.json_io import write_json

        write_json(tmp_path / "d.json", {"a": 1})
    assert {p.name: mode(p) for p in tmp_path.iterdir()} == dict.fromkeys(
        ("a.bin", "b.txt", "c.npz", "d.json"), want)


@pytest.mark.parametrize("mask", [0o022, 0o007])
def test_a_built_fmu_gets_the_umask(tmp_path, mask):
    """The FMU zip (``hpcosim fmu build --out``, the cached builds) was mkstemp's 0600."""
    import zipfile

    from human_fmu.build import _zip_atomically

    tree = tmp_path / "tree"
    (tree / "resources").mkdir(parents=True)
    (tree / "modelDescription.xml").write_text("<fmiModelDescription/>")
    (tree / "resources" / "build_info.json").write_text("{}")
    with umask(mask):
        _zip_atomically(tree, tmp_path / "h.fmu")
    assert mode(tmp_path / "h.fmu") == 0o666 & ~mask
    with zipfile.ZipFile(tmp_path / "h.fmu") as z:
        assert sorted(z.namelist()) == ["modelDescription.xml", "resources/build_info.json"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["h.fmu", "tree"]


@pytest.mark.parametrize("mask", [0o027, 0o002])
def test_a_recording_gets_the_umask(tmp_path, mask):
    """A new recording and one whose stale ``.part`` (a killed run's, mode 0666) is reused
    both end with 0o666 less the umask."""
    stale = tmp_path / ".b.mcap.part"
    stale.write_bytes(b"half a file from a killed run")
    stale.chmod(0o666)
    with umask(mask):
        record(tmp_path / "a.mcap")
        record(tmp_path / "b.mcap")
    assert mode(tmp_path / "a.mcap") == mode(tmp_path / "b.mcap") == 0o666 & ~mask
    assert recorded_times(tmp_path / "b.mcap") == pytest.approx([k * 1e-3 for k in range(50)])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.mcap", "b.mcap"]


# ------------------------------------------------------------------ planted links and files


def test_an_atomic_write_replaces_a_planted_link_never_its_target(tmp_path):
    """A symbolic link (or another user's 0666 file) planted under the output's name in a
    shared folder: the output replaces the name; the link's target is unchanged."""
    v = victim(tmp_path)
    d = shared_folder(tmp_path)
    (d / "gait.json").symlink_to(v)
    planted = d / "tube.json"
    planted.write_bytes(b"planted")
    os.chown(planted, NOBODY, NOBODY)
    planted.chmod(0o666)
    with umask(0o022):
        atomic_write_text(d / "gait.json", '{"ok": 1}\n')
        atomic_write_text(d / "tube.json", '{"ok": 2}\n')
    assert v.read_bytes() == PRECIOUS and mode(v) == 0o600
    for name, text in (("gait.json", '{"ok": 1}\n'), ("tube.json", '{"ok": 2}\n')):
        st = os.lstat(d / name)
        assert stat.S_ISREG(st.st_mode) and st.st_uid == os.geteuid(), name
        assert stat.S_IMODE(st.st_mode) == 0o644 and (d / name).read_text() == text


def test_a_planted_part_link_is_refused_and_its_target_untouched(tmp_path):
    """The attack of issue 39: a symbolic link named like the recording's part file, to a
    root-only file.  The recorder refuses it (one line naming it) and writes nothing; the
    link and its target are unchanged; a recording beside it is complete and correct."""
    v = victim(tmp_path)
    d = shared_folder(tmp_path)
    link = d / ".run.mcap.part"
    link.symlink_to(v)
    with pytest.raises(UnsafePartFileError) as e:
        record(d / "run.mcap")
    msg = str(e.value)
    assert len(msg.splitlines()) == 1 and str(link) in msg and "symbolic link" in msg
    assert v.read_bytes() == PRECIOUS and mode(v) == 0o600
    assert link.is_symlink() and os.readlink(link) == str(v)
    assert not (d / "run.mcap").exists()
    # a dangling link too: nothing is created where it points
    dangling = d / ".gone.mcap.part"
    dangling.symlink_to(tmp_path / "elsewhere" / "created-by-the-run")
    with pytest.raises(UnsafePartFileError, match="symbolic link"):
        record(d / "gone.mcap")
    assert sorted(p.name for p in v.parent.iterdir()) == ["shadow"]
    # the run's own output in the same folder is right
    with umask(0o022):
        record(d / "other.mcap", 300)
    assert recorded_times(d / "other.mcap") == pytest.approx([k * 1e-3 for k in range(300)])
    assert mode(d / "other.mcap") == 0o644
    assert os.stat(d / "other.mcap").st_uid == os.geteuid()


@pytest.mark.skipif(os.geteuid() != 0, reason="planting another user's file needs root")
def test_another_users_part_file_is_refused_untouched(tmp_path):
    """A regular file planted under the part name by another user (mode 0666): refused,
    left as it was (content, owner, mode); before, the recording ended up owned by that
    user, mode 0666."""
    d = shared_folder(tmp_path)
    part = d / ".run.mcap.part"
    part.write_bytes(b"planted by nobody")
    os.chown(part, NOBODY, NOBODY)
    part.chmod(0o666)
    with pytest.raises(UnsafePartFileError) as e:
        record(d / "run.mcap")
    assert str(part) in str(e.value) and f"another user (uid {NOBODY})" in str(e.value)
    st = os.lstat(part)
    assert (st.st_uid, stat.S_IMODE(st.st_mode), part.read_bytes()) == (
        NOBODY, 0o666, b"planted by nobody")
    assert not (d / "run.mcap").exists()


def test_a_fifo_or_hard_link_under_the_part_name_is_refused(tmp_path):
    """A FIFO (which would block an open) and a hard link to a file elsewhere (writing
    would change that file) are refused at once."""
    v = victim(tmp_path)
    os.mkfifo(tmp_path / ".fifo.mcap.part")
    with pytest.raises(UnsafePartFileError, match="not a regular file"):
        record(tmp_path / "fifo.mcap")
    os.link(v, tmp_path / ".hard.mcap.part")
    with pytest.raises(UnsafePartFileError, match="other hard links"):
        record(tmp_path / "hard.mcap")
    assert v.read_bytes() == PRECIOUS
    assert not (tmp_path / "fifo.mcap").exists() and not (tmp_path / "hard.mcap").exists()


def test_a_part_file_replaced_while_recording_is_not_published(tmp_path):
    """Something renamed over the part file during the run: the recorder does not rename
    that to the recording's name, and leaves it alone."""
    path = tmp_path / "run.mcap"
    rec = Recorder(path)
    rec.register_all()
    other = tmp_path / "other"
    other.write_bytes(b"not the run's")
    os.replace(other, rec.part_path)
    with pytest.raises(UnsafePartFileError, match="no longer this run's file"):
        rec.finish()
    assert not path.exists() and rec.part_path.read_bytes() == b"not the run's"


def test_the_in_use_lock_still_holds(tmp_path):
    """The one-writer rule is unchanged: a second recorder of the same path is refused."""
    with Recorder(tmp_path / "run.mcap") as rec:
        rec.register_all()
        with pytest.raises(RecordingInUseError):
            Recorder(tmp_path / "run.mcap")


# ----------------------------------------------------------------------- leftovers of runs


def _python(code: str, tmp: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "TMPDIR": str(tmp)}
    return subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)], env=env,
                            cwd=str(ROOT), stdout=subprocess.PIPE, text=True)


def _killed_after_ready(code: str, tmp: Path) -> int:
    """Run ``code`` until it prints "ready", SIGKILL it; its PID."""
    p = _python(code, tmp)
    try:
        assert p.stdout is not None
        while (line := p.stdout.readline()) and line.strip() != "ready":
            pass
        assert line.strip() == "ready"
        p.send_signal(signal.SIGKILL)
        assert p.wait(30) == -signal.SIGKILL
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    return p.pid


def _run(code: str, tmp: Path) -> str:
    p = _python(code, tmp)
    out, _ = p.communicate(timeout=120)
    assert p.returncode == 0, out
    return out


def _names(d: Path, prefix: str) -> list[str]:
    return sorted(p.name for p in d.iterdir() if p.name.startswith(prefix))


HOLD_CREDS = """
    import sys, time
    from bus_schemas.transport.run_auth import RunCredentials
    c = RunCredentials(in_memory={in_memory})
    print(c.dictionary, flush=True)
    print("ready", flush=True)
    time.sleep(300)
    """


def test_the_run_secret_never_reaches_the_disk_and_dies_with_its_process(tmp_path):
    """On Linux the dictionary is an in-memory file zenoh reads through /proc: a run
    killed by SIGKILL leaves no ``hpcosim-auth-*`` folder (before: one per kill)."""
    p = _python(HOLD_CREDS.format(in_memory=True), tmp_path)
    try:
        assert p.stdout is not None
        dictionary = p.stdout.readline().strip()
        assert p.stdout.readline().strip() == "ready"
        assert dictionary.startswith("/proc/self/fd/")
        fd = dictionary.rsplit("/", 1)[1]
        held = Path(f"/proc/{p.pid}/fd/{fd}")
        assert held.read_text().count(":") == 2  # plant and ctrl, the run's secret
        assert os.readlink(held).startswith("/memfd:hpcosim-auth")
        p.send_signal(signal.SIGKILL)
        p.wait(30)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert list(tmp_path.iterdir()) == []


def test_a_killed_runs_auth_folder_is_removed_at_the_next_start(tmp_path):
    """Where the dictionary must be a file (no memfd): its folder carries the owner's PID;
    the next RunCredentials removes those of dead processes (here one killed by SIGKILL, and
    an old-style folder older than an hour) and keeps a live process's and a fresh one."""
    dead = _killed_after_ready(HOLD_CREDS.format(in_memory=False), tmp_path)
    left = _names(tmp_path, "hpcosim-auth-")
    assert len(left) == 1 and left[0].startswith(f"hpcosim-auth-{dead}-")
    assert (tmp_path / left[0] / "usrpwd.txt").is_file()
    old, fresh = tmp_path / "hpcosim-auth-k2j4_x9a", tmp_path / "hpcosim-auth-p0q1r2s3"
    for d in (old, fresh):
        d.mkdir()
        (d / "usrpwd.txt").write_text("plant:x\nctrl:x\n")
    os.utime(old, (time.time() - 7200, time.time() - 7200))
    live = _python(HOLD_CREDS.format(in_memory=False), tmp_path)
    try:
        assert live.stdout is not None
        live.stdout.readline()
        assert live.stdout.readline().strip() == "ready"
        assert _names(tmp_path, "hpcosim-auth-") == sorted(
            [fresh.name, next(n for n in os.listdir(tmp_path)
                              if n.startswith(f"hpcosim-auth-{live.pid}-"))])
        _run("""
            from bus_schemas.transport.run_auth import RunCredentials
            RunCredentials(in_memory=False).close()
            """, tmp_path)
        names = _names(tmp_path, "hpcosim-auth-")
        assert fresh.name in names and any(n.startswith(f"hpcosim-auth-{live.pid}-")
                                           for n in names) and len(names) == 2
    finally:
        live.kill()
        live.wait()


@pytest.fixture(scope="module")
def fmu_path(tmp_path_factory, model, template_gait):
    return built_fmu(tmp_path_factory, model, template_gait)[0]


HOLD_FMU = """
    import time
    from human_fmu.instance import HumanFmu
    f = HumanFmu({fmu!r})
    print("ready", flush=True)
    time.sleep(300)
    """


def _size_kib(d: Path) -> float:
    return sum(p.stat().st_size for p in d.rglob("*") if p.is_file()) / 1024


def test_a_killed_runs_extracted_fmu_is_removed_at_the_next_start(tmp_path, fmu_path):
    """The FMU is extracted into ``hpcosim-fmu-<pid>-*``, locked by its process: after a
    SIGKILL the folder (the FMU's ~950 KiB) is left; the next HumanFmu removes it, keeps the
    folder of a process still running, and removes its own when freed."""
    dead = _killed_after_ready(HOLD_FMU.format(fmu=str(fmu_path)), tmp_path)
    left = _names(tmp_path, "hpcosim-fmu-")
    assert len(left) == 1 and left[0].startswith(f"hpcosim-fmu-{dead}-")
    assert _size_kib(tmp_path / left[0]) > 500
    live = _python(HOLD_FMU.format(fmu=str(fmu_path)), tmp_path)
    try:
        assert live.stdout is not None and live.stdout.readline().strip() == "ready"
        _run(f"""
            from human_fmu.instance import HumanFmu
            HumanFmu({str(fmu_path)!r}).free()
            """, tmp_path)
        names = _names(tmp_path, "hpcosim-fmu-")
        assert len(names) == 1 and names[0].startswith(f"hpcosim-fmu-{live.pid}-")
    finally:
        live.kill()
        live.wait()
    _run(f"""
        from human_fmu.instance import HumanFmu
        HumanFmu({str(fmu_path)!r}).free()
        """, tmp_path)
    assert list(tmp_path.iterdir()) == []  # the second one killed too: gone now


@pytest.fixture(scope="module")
def cosim_files(tmp_path_factory, fmu_path, template_gait):
    from hp_model.force_tube import save_tube
    from tests.controller_support import tube_about_nominal

    d = tmp_path_factory.mktemp("cosim-out")
    tube = d / "tube.json"
    save_tube(tube, tube_about_nominal(template_gait, (0.1, 0.15, 0.02)))
    return {"fmu": fmu_path, "gait": fmu_path.parent / "gait.json", "tube": tube}


def _hpcosim_run(files, record: Path, tmp: Path, mask: int = 0o022,
                 steps: int = 2) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "TMPDIR": str(tmp)}
    return subprocess.Popen(
        [sys.executable, "-m", "orchestrator.cli", "run", "--controller", "clfqp",
         "--gait", str(files["gait"]), "--tube", str(files["tube"]), "--fmu",
         str(files["fmu"]), "--steps", str(steps), "--record", str(record)],
        env=env, cwd=str(ROOT), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        umask=mask)


def test_hpcosim_run_killed_leaves_nothing_once_the_next_run_starts(tmp_path, cosim_files):
    """``hpcosim run --record`` killed with SIGKILL mid-run (its controller node exits once
    the plant is gone): the next ``hpcosim run`` removes what the killed one left in the
    temporary folder; it leaves nothing itself, and its recording has the umask's mode."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    out = tmp_path / "out"
    out.mkdir()
    p = _hpcosim_run(cosim_files, out / "killed.mcap", tmp, steps=20)
    part = out / ".killed.mcap.part"
    deadline = time.monotonic() + 120
    try:
        while not (part.exists() and part.stat().st_size > 0):
            assert p.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
        p.send_signal(signal.SIGKILL)
        p.wait(30)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
        if p.stderr is not None:
            p.stderr.close()
    assert _names(tmp, "hpcosim-fmu-") != [] and _names(tmp, "hpcosim-auth-") == []
    q = _hpcosim_run(cosim_files, out / "next.mcap", tmp, mask=0o027)
    _, err = q.communicate(timeout=300)
    assert q.returncode in (0, 1), err  # 1: the walk's own outcome (a fall on a busy host)
    assert _names(tmp, "hpcosim-") == []
    assert mode(out / "next.mcap") == 0o640


def test_hpcosim_run_refuses_a_planted_part_link_in_one_line(tmp_path, cosim_files):
    """The issue's case through the CLI: a planted link named like the part file: exit 2,
    one line naming it, the root-only target unchanged, no recording."""
    v = victim(tmp_path)
    d = shared_folder(tmp_path)
    (d / ".run.mcap.part").symlink_to(v)
    p = _hpcosim_run(cosim_files, d / "run.mcap", tmp_path)
    _, err = p.communicate(timeout=300)
    lines = err.decode().strip().splitlines()
    assert p.returncode == 2 and len(lines) == 1, err
    assert str(d / ".run.mcap.part") in lines[0] and "symbolic link" in lines[0]
    assert v.read_bytes() == PRECIOUS and mode(v) == 0o600
    assert not (d / "run.mcap").exists()
