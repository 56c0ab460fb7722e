"""Issue 39: bad invocations of every verb of ``hpcosim``, each one line naming the option or
field, exit status 2, no traceback and nothing written.

The table (:data:`CASES`, over 100 invocations) runs each in a fresh working folder holding
only the inputs it needs; after the call the folder holds exactly those (no output, no
``.part`` file, no folder made for an output).  Among them the 14 cases the issue's probe
found printing a traceback: ``run --max-time inf``, ``run --perturb human:nan``,
``--controller bogus`` on ``replay`` and ``controller serve``, a non-loopback endpoint on
``replay --to-bus`` and ``controller serve``, a bus TOML with a wrong type, a bad run id and
an unreachable ``--scheduler``."""

from __future__ import annotations

import os
import signal
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

from orchestrator.cli import main
from tests.fmu_support import built_fmu

DATA = Path(__file__).resolve().parent / "data" / "controller"
GAIT, TUBE = str(DATA / "gait_demo.json"), str(DATA / "tube_demo.json")
SPEC = str(Path(__file__).resolve().parents[1] / "examples" / "sweep" / "quick.toml")
GAIT_HASH = "dc2d8a17ef60bd76"  # GAIT's (tube_demo.json is made for it)
SECRET = "k2Vq9yTQ0w8yJ4mU3lZP5nq7X1c6bA-s"  # 32 characters: a valid key file's line


@dataclass
class Folder:
    """The working folder of one case and the inputs written into it."""

    root: Path
    other_fmu: Path  # an FMU built for another gait than GAIT (the template gait's)

    def file(self, name: str, text: str | bytes, mode: int = 0o600) -> str:
        p = self.root / name
        p.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(text, bytes):
            p.write_bytes(text)
        else:
            p.write_text(text)
        p.chmod(mode)
        return str(p)

    def key(self, text: str = SECRET + "\n", mode: int = 0o600, name: str = "lab.key") -> str:
        return self.file(name, text, mode)

    def bus(self, text: str, name: str = "bus.toml") -> str:
        return self.file(name, text, 0o644)

    def out(self, name: str) -> str:
        """A path for an output (nothing may appear there)."""
        return str(self.root / name)

    def garbage(self, name: str = "garbage.bin") -> str:
        return self.file(name, bytes(range(256)) * 4, 0o644)

    def fmu_with(self, **build: str) -> str:
        """A copy of :attr:`other_fmu` whose build identity says ``build``
        (``model_hash=...``) or, with no arguments, has no identity at all."""
        dst = self.root / "edited.fmu"
        with zipfile.ZipFile(self.other_fmu) as src, zipfile.ZipFile(dst, "w") as z:
            for info in src.infolist():
                data = src.read(info)
                if info.filename == "modelDescription.xml":
                    text = data.decode()
                    if build:
                        for k, v in build.items():
                            i = text.index(f'{k}="') + len(k) + 2
                            text = text[:i] + v + text[text.index('"', i):]
                    else:
                        a, b = text.index("<VendorAnnotations>"), text.index(
                            "</VendorAnnotations>") + len("</VendorAnnotations>")
                        text = text[:a] + text[b:]
                    data = text.encode()
                z.writestr(info, data)
        return str(dst)


Argv = Callable[[Folder], list[str]]
SERVE = ["controller", "serve", "--controller", "pd", "--gait", GAIT, "--tube", TUBE]
RUN = ["run", "--controller", "pd", "--gait", GAIT, "--tube", TUBE, "--steps", "1"]


def serve(*more: str) -> Argv:
    return lambda f: [*SERVE, *more]


def serve_bus(toml: str, *more: str) -> Argv:
    return lambda f: [*SERVE, "--bus", f.bus(toml), *more]


def serve_key(text: str = SECRET + "\n", mode: int = 0o600, *more: str) -> Argv:
    return lambda f: [*SERVE, "--run-id", "k", "--key", f.key(text, mode), *more]


def run(*more: str) -> Argv:
    return lambda f: [*RUN, *more]


def run_rec(*more: str) -> Argv:
    """``run`` recording into the working folder: nothing may be left there."""
    return lambda f: [*RUN, "--record", f.out("rec/run.mcap"), *more]


def to_bus(toml: str) -> Argv:
    return lambda f: ["replay", f.garbage("rec.mcap"), "--to-bus", f.bus(toml)]


def sweep(scheduler: str) -> Argv:
    return lambda f: ["sweep", "run", SPEC, "--out", f.out("sweep"), "--scheduler", scheduler]


#: (id, argv, words the one line must hold): the 14 cases of the issue come first
CASES: list[tuple[str, Argv, tuple[str, ...]]] = [
    ("run max-time inf", run_rec("--max-time", "inf"), ("--max-time",)),
    ("run perturb human:nan", run_rec("--perturb", "human:nan"), ("--perturb", "AMPLITUDE")),
    ("replay controller bogus", lambda f: ["replay", f.garbage("r.mcap"), "--controller",
                                           "bogus"], ("--controller", "bogus")),
    ("serve controller bogus", lambda f: [*SERVE[:3], "bogus", *SERVE[4:]],
     ("--controller", "bogus")),
    ("to-bus listen 0.0.0.0", to_bus('listen = ["tcp/0.0.0.0:7447"]\n'),
     ("listen endpoint", "loopback")),
    ("to-bus connect 192.168", to_bus('connect = "tcp/192.168.1.10:7447"\n'),
     ("connect endpoint", "loopback")),
    ("serve listen 0.0.0.0", serve("--listen", "tcp/0.0.0.0:7447"), ("--listen", "loopback")),
    ("serve connect 10.0.0.2", serve("--connect", "tcp/10.0.0.2:7447"),
     ("--connect", "loopback")),
    ("serve listen [::]", serve("--listen", "tcp/[::]:0"), ("--listen", "loopback")),
    ("to-bus allow_remote string", to_bus('allow_remote = "false"\n'),
     ("allow_remote", "true or false")),
    ("serve bus allow_remote string",
     serve_bus('allow_remote = "false"\nlisten = ["tcp/0.0.0.0:7447"]\n'),
     ("allow_remote", "true or false")),
    ("serve run-id slash", serve("--run-id", "a/b"), ("--run-id",)),
    ("serve bus run_id wildcard", serve_bus('run_id = "run*"\n'), ("run_id",)),
    ("sweep scheduler refused port", sweep("tcp://127.0.0.1:1"), ("--scheduler",)),
    # -- run: the co-simulation's own values, the FMU's build identity
    ("run max-time nan", run_rec("--max-time", "nan"), ("--max-time",)),
    ("run max-time 1e308", run_rec("--max-time", "1e308"), ("--max-time",)),
    ("run perturb human:inf", run_rec("--perturb", "human:inf"), ("--perturb",)),
    ("run perturb human negative", run_rec("--perturb", "human:-0.1"), ("--perturb",)),
    ("run perturb human seed word", run_rec("--perturb", "human:0.01:x"), ("SEED",)),
    ("run perturb human seed negative", run_rec("--perturb", "human:0.01:-1"), ("SEED",)),
    ("run perturb human seed 2**31", run_rec("--perturb", "human:0.01:2147483648"),
     ("SEED",)),
    ("run perturb human extra part", run_rec("--perturb", "human:0.01:1:2"),
     ("--perturb", "too many")),
    ("run perturb drop word", run_rec("--perturb", "drop:x"), ("--perturb", "START")),
    ("run perturb drop negative", run_rec("--perturb", "drop:-1"), ("START",)),
    ("run perturb drop every 0", run_rec("--perturb", "drop:1:0"), ("EVERY",)),
    ("run perturb drop count 0", run_rec("--perturb", "drop:1:2:0"), ("COUNT",)),
    ("run perturb drop extra part", run_rec("--perturb", "drop:1:2:3:4"), ("too many",)),
    ("run perturb stall 0 ms", run_rec("--perturb", "stall:10:0"), ("MS",)),
    ("run perturb stall nan ms", run_rec("--perturb", "stall:10:nan"), ("MS",)),
    ("run perturb kill word", run_rec("--perturb", "kill:soon"), ("START",)),
    ("run perturb bogus", run_rec("--perturb", "bogus"), ("--perturb", "bogus")),
    ("run perturb none with part", run_rec("--perturb", "none:1"), ("--perturb",)),
    ("run controller bogus", lambda f: [*RUN[:2], "bogus", *RUN[3:]], ("--controller",)),
    ("run mode bogus", run_rec("--mode", "bogus"), ("--mode",)),
    ("run steps 0", run_rec("--steps", "0"), ("--steps",)),
    ("run fmu of another gait", lambda f: [*RUN, "--fmu", str(f.other_fmu), "--record",
                                           f.out("run.mcap")], ("--fmu", "another gait")),
    ("run fmu of another model", lambda f: [*RUN, "--fmu", f.fmu_with(
        model_hash="0123456789abcdef")], ("--fmu", "another subject or device")),
    ("run fmu without identity", lambda f: [*RUN, "--fmu", f.fmu_with()],
     ("edited.fmu", "build identity")),
    ("run fmu garbage", lambda f: [*RUN, "--fmu", f.garbage("h.fmu")], ("h.fmu",)),
    ("run fmu missing", lambda f: [*RUN, "--fmu", f.out("none.fmu")], ("none.fmu",)),
    ("run gait garbage", lambda f: [*RUN[:4], f.garbage("g.json"), *RUN[5:]], ("g.json",)),
    ("run tube missing", lambda f: [*RUN[:6], f.out("t.json"), *RUN[7:]], ("t.json",)),
    ("run tube of another gait", lambda f: [*RUN[:6], f.file("t.json", (DATA / "tube_demo.json")
                                            .read_text().replace(GAIT_HASH, "0" * 16)),
                                            *RUN[7:]], ("t.json",)),
    ("run subject missing", run_rec("--subject", "/nonexistent/subject.toml"),
     ("subject.toml",)),
    ("run record under a file", lambda f: [*RUN, "--record", f.file("plain", "x", 0o644)
                                           + "/run.mcap"], ("--record",)),
    # -- controller serve: the key
    ("serve zenoh without key", serve("--run-id", "k"), ("--key",)),
    ("serve key missing", lambda f: [*SERVE, "--key", f.out("none.key")], ("none.key",)),
    ("serve key world-readable", serve_key(mode=0o644), ("lab.key", "chmod 600")),
    ("serve key group-readable", serve_key(mode=0o640), ("lab.key", "chmod 600")),
    ("serve key others-writable", serve_key(mode=0o602), ("lab.key", "chmod 600")),
    ("serve key short", serve_key("short\n"), ("lab.key", "16")),
    ("serve key empty", serve_key(""), ("lab.key", "one line")),
    ("serve key two lines", serve_key(f"{SECRET}\n{SECRET}\n"), ("lab.key", "one line")),
    ("serve key with colon", serve_key(f"{SECRET}:x\n"), ("lab.key", "':'")),
    ("serve key with space", serve_key(f"{SECRET} x\n"), ("lab.key",)),
    ("serve key not text", lambda f: [*SERVE, "--key", f.file("b.key", b"\xff" * 40)],
     ("b.key", "UTF-8")),
    ("serve key a folder", lambda f: [*SERVE, "--key", str(f.root)], ("--key",)),
    ("serve key on virtual", lambda f: [*SERVE, "--interface", "virtual", "--key", f.key()],
     ("--key", "zenoh")),
    ("serve bus key_file relative missing", serve_bus('key_file = "lab.key"\n'),
     ("lab.key",)),
    ("serve bus key_file world-readable",
     lambda f: [*SERVE, "--bus", f.bus(f'key_file = "{f.key(mode=0o604)}"\n')],
     ("lab.key", "chmod 600")),
    ("serve auth-stdin is the node's", serve("--auth-stdin"), ("--auth-stdin",)),
    # -- controller serve: every field of the bus, from options and from a file
    ("serve run-id empty", serve("--run-id", ""), ("--run-id",)),
    ("serve run-id too long", serve("--run-id", "r" * 129), ("--run-id",)),
    ("serve run-id space", serve("--run-id", "a b"), ("--run-id",)),
    ("serve listen not an endpoint", serve("--listen", "nonsense"), ("--listen",)),
    ("serve listen port too big", serve("--listen", "tcp/127.0.0.1:99999"),
     ("--listen", "65535")),
    ("serve connect no port", serve("--connect", "tcp/127.0.0.1"), ("--connect",)),
    ("serve interface unknown", serve("--interface", "no-such-can"),
     ("--interface", "no-such-can")),
    ("serve channel on zenoh", serve("--channel", "can0"), ("--channel", "zenoh")),
    ("serve listen on virtual", serve("--interface", "virtual", "--listen",
                                      "tcp/127.0.0.1:7447"), ("--listen", "zenoh")),
    ("serve udp_multicast without allow_remote", serve("--interface", "udp_multicast"),
     ("--interface", "allow_remote")),
    ("serve watchdog-ms inf", serve("--interface", "virtual", "--watchdog-ms", "inf"),
     ("--watchdog-ms",)),
    ("serve watchdog-ms 0", serve("--watchdog-ms", "0"), ("--watchdog-ms",)),
    ("serve bus interface integer", serve_bus("interface = 5\n"), ("interface", "string")),
    ("serve bus interface empty", serve_bus('interface = ""\n'), ("interface",)),
    ("serve bus run_id integer", serve_bus("run_id = 5\n"), ("run_id", "string")),
    ("serve bus run_id list", serve_bus('run_id = ["a"]\n'), ("run_id", "string")),
    ("serve bus channel integer", serve_bus('interface = "virtual"\nchannel = 5\n'),
     ("channel", "string")),
    ("serve bus listen integer", serve_bus("listen = 5\n"), ("listen", "list")),
    ("serve bus listen list of numbers", serve_bus("listen = [1, 2]\n"), ("listen", "list")),
    ("serve bus connect table", serve_bus("connect = {a = 1}\n"), ("connect", "list")),
    ("serve bus connect not loopback", serve_bus('connect = ["tcp/1.2.3.4:7447"]\n'),
     ("connect endpoint", "loopback")),
    ("serve bus allow_remote integer", serve_bus("allow_remote = 1\n"),
     ("allow_remote", "true or false")),
    ("serve bus allow_remote on virtual", serve_bus(
        'interface = "virtual"\nallow_remote = true\n'), ("allow_remote",)),
    ("serve bus key_file integer", serve_bus("key_file = 5\n"), ("key_file", "string")),
    ("serve bus options string", serve_bus('options = "x"\n'), ("options", "table")),
    ("serve bus options unknown", serve_bus("[options]\nbogus = 1\n"), ("options.bogus",)),
    ("serve bus poll_us negative", serve_bus("[options]\npoll_us = -1\n"),
     ("options.poll_us",)),
    ("serve bus poll_us string", serve_bus('[options]\npoll_us = "fast"\n'),
     ("options.poll_us",)),
    ("serve bus poll_us nan", serve_bus("[options]\npoll_us = nan\n"), ("options.poll_us",)),
    ("serve bus low_latency string", serve_bus('[options]\nlow_latency = "yes"\n'),
     ("options.low_latency", "true or false")),
    ("serve bus rx_queue_size 0", serve_bus("[options]\nrx_queue_size = 0\n"),
     ("options.rx_queue_size",)),
    ("serve bus rx_queue_size float", serve_bus("[options]\nrx_queue_size = 2.5\n"),
     ("options.rx_queue_size",)),
    ("serve bus mode router", serve_bus('[options]\nmode = "router"\n'), ("options.mode",)),
    ("serve bus zenoh_options listen", serve_bus(
        '[options.zenoh_options]\n"listen/endpoints" = ["tcp/0.0.0.0:7447"]\n'),
     ("options.zenoh_options", "allow_remote")),
    ("serve bus zenoh_options string", serve_bus('[options]\nzenoh_options = "x"\n'),
     ("options.zenoh_options", "table")),
    ("serve bus options a field", serve_bus(
        'interface = "virtual"\n[options]\nchannel = "x"\n'), ("options", "fields")),
    ("serve bus unknown key", serve_bus('interface = "zenoh"\nbogus = 1\n'), ("bogus",)),
    ("serve bus not TOML", serve_bus("interface = \n"), ("bus.toml",)),
    ("serve bus JSON bool as string", lambda f: [*SERVE, "--bus", f.bus(
        '{"allow_remote": "true"}', "bus.json")], ("bus.json", "allow_remote")),
    ("serve bus JSON a list", lambda f: [*SERVE, "--bus", f.bus("[1]", "bus.json")],
     ("bus.json",)),
    ("serve bus not UTF-8", lambda f: [*SERVE, "--bus", f.garbage("bus.toml")], ("bus.toml",)),
    ("serve bus missing", lambda f: [*SERVE, "--bus", f.out("none.toml")], ("none.toml",)),
    # -- replay
    ("replay not an MCAP", lambda f: ["replay", f.garbage("r.mcap")], ("r.mcap",)),
    ("replay missing", lambda f: ["replay", f.out("none.mcap")], ("none.mcap",)),
    ("to-bus not an MCAP", to_bus('interface = "virtual"\n'), ("rec.mcap",)),
    ("to-bus run_id integer", to_bus("run_id = 5\n"), ("run_id",)),
    ("to-bus interface unknown", to_bus('interface = "no-such-can"\n'), ("no-such-can",)),
    ("to-bus key world-readable", lambda f: ["replay", f.garbage("r.mcap"), "--to-bus",
                                             f.bus(f'key_file = "{f.key(mode=0o644)}"\n')],
     ("lab.key",)),
    ("to-bus speed negative", lambda f: ["replay", f.garbage("r.mcap"), "--to-bus",
                                         f.bus(""), "--speed", "-1"], ("--speed",)),
    # -- sweep run --scheduler
    ("sweep scheduler no port", sweep("bogus"), ("--scheduler",)),
    ("sweep scheduler udp", sweep("udp://1.2.3.4:1"), ("--scheduler", "udp")),
    ("sweep scheduler port too big", sweep("tcp://127.0.0.1:99999"), ("--scheduler",)),
    ("sweep scheduler tls unconfigured", sweep("tls://127.0.0.1:1"), ("--scheduler", "TLS")),
    ("sweep scheduler ucx", sweep("ucx://127.0.0.1:1"), ("--scheduler", "ucx")),
    ("sweep scheduler inproc", sweep("inproc://x"), ("--scheduler",)),
    ("sweep scheduler empty", sweep(""), ("--scheduler",)),
    ("sweep scheduler colon", sweep(":"), ("--scheduler",)),
    ("sweep scheduler bad ipv6", sweep("tcp://[::1:1"), ("--scheduler",)),
    ("sweep scheduler and workers", lambda f: ["sweep", "run", SPEC, "--out", f.out("s"),
                                               "--scheduler", "tcp://127.0.0.1:1",
                                               "--workers", "1"], ("--workers",)),
    # -- the other verbs
    ("model check subject missing", lambda f: ["model", "check", "--subject",
                                               f.out("s.toml")], ("s.toml",)),
    ("model check backend bogus", lambda f: ["model", "check", "--backend", "bogus"],
     ("--backend",)),
    ("mocap synth steps nan", lambda f: ["mocap", "synth", "--out", f.out("m"), "--steps",
                                         "nan"], ("--steps",)),
    ("mocap synth source bogus", lambda f: ["mocap", "synth", "--out", f.out("m"),
                                            "--source", "bogus"], ("source", "bogus")),
    ("mocap inspect garbage", lambda f: ["mocap", "inspect", f.garbage("take.csv")],
     ("take.csv",)),
    ("mocap process missing", lambda f: ["mocap", "process", f.out("take.c3d"), "--out",
                                         f.out("steps.npz")], ("take.c3d",)),
    ("gait fit garbage", lambda f: ["gait", "fit", f.garbage("steps.npz"), "--out",
                                    f.out("gait.json")], ("steps.npz",)),
    ("gait fit degree 0", lambda f: ["gait", "fit", f.garbage("steps.npz"), "--out",
                                     f.out("gait.json"), "--degree", "0"], ("--degree",)),
    ("gait export garbage", lambda f: ["gait", "export", f.garbage("g.json"), "--out",
                                       f.out("g.csv")], ("g.json",)),
    ("gait library gait garbage", lambda f: ["gait", "library", f.garbage("steps.npz"),
                                             "--gait", f.garbage("g.json"), "--out",
                                             f.out("lib.json")], ("g.json",)),
    ("gait library paper gait", lambda f: ["gait", "library", f.garbage("steps.npz"),
                                           "--gait", GAIT, "--out", f.out("lib.json")],
     ("kind",)),
    ("gait library speeds bogus", lambda f: ["gait", "library", f.garbage("steps.npz"),
                                             "--gait", GAIT, "--out", f.out("lib.json"),
                                             "--speeds", "0.8,x"], ("--speeds",)),
    ("run speed profile without library", run_rec("--speed-profile", "0:0.9"),
     ("--speed-profile", "--library")),
    ("run speed profile bogus", lambda f: [*RUN, "--library", f.garbage("lib.json"),
                                           "--speed-profile", "0:0.9,x"],
     ("--speed-profile", "'x'")),
    ("run library on the paper's graph", lambda f: [*RUN, "--record", f.out("rec/run.mcap"),
                                                    "--library", f.garbage("lib.json")],
     ("--library", "lib.json", "paper")),
    ("tube fit garbage", lambda f: ["tube", "fit", f.garbage("steps.npz"), "--gait", GAIT,
                                    "--out", f.out("tube.json")], ("steps.npz",)),
    ("tube refit garbage", lambda f: ["tube", "refit", f.garbage("r.mcap"), "--gait", GAIT,
                                      "--out", f.out("tube.json")], ("r.mcap",)),
    ("experiments steps 0", lambda f: ["experiments", "--gait", GAIT, "--tube", TUBE,
                                       "--out", f.out("x"), "--steps", "0"], ("--steps",)),
    ("experiments tube garbage", lambda f: ["experiments", "--gait", GAIT, "--tube",
                                            f.garbage("t.json"), "--out", f.out("x")],
     ("t.json",)),
    ("demo steps -1", lambda f: ["demo", "--out", f.out("d"), "--steps", "-1"], ("--steps",)),
    ("fmu build gait garbage", lambda f: ["fmu", "build", "--gait", f.garbage("g.json"),
                                          "--out", f.out("h.fmu")], ("g.json",)),
    ("fmu build fmi 4", lambda f: ["fmu", "build", "--gait", GAIT, "--out", f.out("h.fmu"),
                                   "--fmi", "4"], ("--fmi",)),
    ("animate garbage recording", lambda f: ["animate", f.garbage("r.mcap"), "--out",
                                             f.out("w.gif")], ("r.mcap",)),
    ("animate fps 0", lambda f: ["animate", "clfqp", "--out", f.out("w.gif"), "--fps", "0"],
     ("--fps",)),
    ("recording recover garbage", lambda f: ["recording", "recover", f.garbage(".r.mcap.part"),
                                             "--out", f.out("r.mcap")], ("r.mcap",)),
    ("recording export garbage", lambda f: ["recording", "export", f.garbage("r.mcap"),
                                            "--out", f.out("r.csv")], ("r.mcap",)),
    ("sweep report no sweep", lambda f: ["sweep", "report", f.out("none")], ("none",)),
    ("sweep replay no sweep", lambda f: ["sweep", "replay", f.out("none"), "clfqp/human/0"],
     ("none",)),
    ("sweep run fmu of another gait", lambda f: ["sweep", "run", f.file("spec.toml", (
        f'name = "s"\ngait = "{GAIT}"\ntube = "{TUBE}"\ncontrollers = ["pd"]\ndraws = 1\nseed = 1\n'
        f'steps = 1\nbackend = "fmu"\nfmu = "{f.other_fmu}"\n[families.nominal]\n')),
        "--out", f.out("s"), "--workers", "1"], ("the spec's fmu", "another gait")),
    ("sweep run spec garbage", lambda f: ["sweep", "run", f.garbage("spec.toml"), "--out",
                                          f.out("s")], ("spec.toml",)),
]


GROUPS = ("model", "mocap", "gait", "tube", "fmu", "sweep", "recording", "controller")


def test_the_table_is_large_and_covers_every_verb(tmp_path):
    from tests.test_cli_errors import LEAVES

    assert len(CASES) >= 100
    assert len({c[0] for c in CASES}) == len(CASES)
    f = Folder(tmp_path, tmp_path / "other.fmu")
    f.fmu_with = lambda **_: "edited.fmu"  # type: ignore[method-assign]
    verbs = set()
    for _, argv, _ in CASES:
        a = argv(f)
        verbs.add(tuple(a[:2]) if a[0] in GROUPS else (a[0],))
    assert verbs == set(LEAVES)  # every verb of the command line, no other


@pytest.fixture(scope="module")
def other_fmu(tmp_path_factory, model, template_gait) -> Path:
    """An FMU built for the template gait: another gait than ``GAIT``."""
    return built_fmu(tmp_path_factory, model, template_gait)[0]


def _tree(root: Path) -> dict[str, int]:
    """Every path under ``root`` with its mode (files, folders, links alike)."""
    return {str(p.relative_to(root)): p.lstat().st_mode for p in root.rglob("*")}


class _HungError(Exception):
    pass


def _alarm(_signum, _frame):
    raise _HungError("a bad invocation ran for 120 s instead of failing")


@pytest.mark.parametrize(("argv", "words"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_a_bad_invocation_is_one_line_exit_2_and_writes_nothing(capsys, tmp_path, monkeypatch,
                                                                other_fmu, argv, words):
    folder = Folder(tmp_path / "work", other_fmu)
    folder.root.mkdir()
    args = argv(folder)
    before = _tree(folder.root)
    monkeypatch.chdir(folder.root)
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(120)
    try:
        rc = main(args)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert rc == 2, (args, err)
    assert len(lines) == 1 and lines[0].startswith("hpcosim: error: "), (args, err)
    assert "Traceback" not in err
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert _tree(folder.root) == before, args  # no output, no .part, no folder made


def test_the_part_of_a_failed_run_is_gone_too(tmp_path, other_fmu, template_gait):
    """``run --record X`` failing before its first tick (here: a controller process that is
    not alive within the start timeout, after the recording was opened) leaves neither X,
    nor its ``.part``, nor the folder made for it."""
    from hp_model.force_tube import save_tube
    from orchestrator.cosim.config import CosimConfig, CosimError
    from orchestrator.cosim.master import run_cosim
    from tests.controller_support import tube_about_nominal

    tube = tmp_path / "tube.json"
    save_tube(tube, tube_about_nominal(template_gait, (0.1, 0.15, 0.02)))
    cfg = CosimConfig(controller="pd", gait=other_fmu.parent / "gait.json", tube=tube,
                      fmu=other_fmu, steps=1, record=tmp_path / "new" / "run.mcap",
                      start_timeout=1e-3)
    with pytest.raises(CosimError, match="not alive"):
        run_cosim(cfg)
    assert os.listdir(tmp_path) == ["tube.json"]
