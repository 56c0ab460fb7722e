"""``hpcosim gait export`` and ``hpcosim recording export`` (issue 40): a gait or a run as CSV
and OpenSim ``.mot``, read back and checked against the gait's own trajectory, the model's
dynamics and the recording's messages; the ``.mot`` files parsed by OpenSim's rules
(opensim-core ``DelimFileAdapter``: header lines up to ``endheader``, ``key=value`` pairs,
a tab-separated label line starting with ``time``, rows of as many numbers, time strictly
increasing)."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest

from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.gait_artifact import load_gait
from hp_model.human_prosthesis import COORDS
from hp_model.tables import Column, MotTable, TableError, csv_text, mot_text
from orchestrator.cli import main

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "tests" / "data" / "controller" / "gait_demo.json"


# ------------------------------------------------------------------------ readers (OpenSim's)


def read_mot(path: Path) -> tuple[str, dict[str, str], list[str], np.ndarray]:
    """(name, header key=value pairs, labels, data (nRows, nColumns)) by OpenSim's rules,
    checking what its reader checks and that nRows / nColumns match the data."""
    lines = path.read_text().split("\n")
    assert lines[-1] == "" and "\r" not in path.read_text()
    name, meta, k = lines[0], {}, 1
    while not re.fullmatch(r"[ \t]*endheader[ \t]*", lines[k]):
        m = re.fullmatch(r"(.*)=(.*)", lines[k])
        if m:
            meta[m.group(1).strip()] = m.group(2).strip()
        k += 1
    labels = lines[k + 1].split("\t")
    assert labels[0] == "time" and len(set(labels)) == len(labels)
    rows = [r.split("\t") for r in lines[k + 2:-1]]
    assert all(len(r) == len(labels) for r in rows)
    data = np.array(rows, dtype=float)
    assert int(meta["nRows"]) == data.shape[0] and int(meta["nColumns"]) == data.shape[1]
    assert np.all(np.diff(data[:, 0]) > 0)  # OpenSim's TimestampLessThanEqualToPrevious
    return name, meta, labels, data


def read_csv(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


def column(header: list[str], rows: list[list[str]], name: str) -> np.ndarray:
    """A numeric column by its header (``name [unit]``); empty cells are NaN."""
    i = header.index(name)
    return np.array([float(r[i]) if r[i] else np.nan for r in rows])


# ------------------------------------------------------------------------------- the gait


@pytest.fixture(scope="module")
def gait_files(tmp_path_factory, model):
    out = tmp_path_factory.mktemp("gait_export") / "demo"
    assert main(["gait", "export", str(DEMO), "--out", str(out)]) == 0
    return out, load_gait(DEMO, model.parameter_hash())


def _stride(gait, name):
    """The trajectory's field ``name`` over one stride, built here independently of the
    export: ps, then pns without its first sample (the impact's post state), time from 0."""
    ps, pns = gait.trajectory[Domain.PS], gait.trajectory[Domain.PNS]
    if name == "t":
        return np.concatenate([ps["t"] - ps["t"][0],
                               pns["t"][1:] - pns["t"][0] + ps["t"][-1] - ps["t"][0]])
    return np.hstack([ps[name], pns[name][:, 1:]]).T


def test_gait_csv_is_the_trajectory(gait_files, model):
    out, gait = gait_files
    header, rows = read_csv(out / "stride.csv")
    n_ps, n_pns = (gait.trajectory[d]["t"].size for d in PAPER_DOMAINS)
    assert len(rows) == n_ps + n_pns - 1  # the impact's two states: one row
    assert header[:2] == ["time [s]", "domain"]
    assert header[2:14] == [f"{c} [{'m' if c in ('x_B', 'z_B', 'x_f', 'z_f') else 'rad'}]"
                            for c in COORDS]
    t = column(header, rows, "time [s]")
    np.testing.assert_array_equal(t, _stride(gait, "t"))
    assert t[0] == 0.0 and t[-1] == pytest.approx(sum(gait.durations.values()), abs=1e-12)
    assert [r[1] for r in rows] == [Domain.PS.value] * n_ps + [Domain.PNS.value] * (n_pns - 1)
    q = _stride(gait, "q")
    for i in range(len(COORDS)):  # bit for bit: the CSV's numbers round-trip
        np.testing.assert_array_equal(column(header, rows, header[2 + i]), q[:, i])
    # the knee angles at a sample in each domain, by name
    k = 20
    assert column(header, rows, "th_pk [rad]")[k] == gait.trajectory[Domain.PS]["q"][10, k]
    assert column(header, rows, "th_lk [rad]")[n_ps - 1 + k] == \
        gait.trajectory[Domain.PNS]["q"][4, k]
    # joint torques: the gear ratio times the motor torque for the prosthesis
    u = _stride(gait, "u")
    ratio = model.device.prosthesis.knee.gear_ratio.value
    assert ratio > 1
    np.testing.assert_allclose(column(header, rows, "th_pk_torque [N m]"), ratio * u[:, 4],
                               rtol=1e-12)
    np.testing.assert_allclose(column(header, rows, "th_lh_torque [N m]"), u[:, 0], rtol=1e-12)


def test_gait_kinematics_mot_follows_opensim(gait_files):
    out, gait = gait_files
    name, meta, labels, data = read_mot(out / "kinematics.mot")
    assert name == "Coordinates"
    assert meta == {"version": "1", "nRows": "81", "nColumns": "13", "inDegrees": "yes"}
    assert labels == ["time", *COORDS]
    q = _stride(gait, "q")
    np.testing.assert_array_equal(data[:, 0], _stride(gait, "t"))
    for i, c in enumerate(COORDS):
        want = q[:, i] * 180.0 / np.pi if c.startswith("th_") else q[:, i]
        np.testing.assert_allclose(data[:, 1 + i], want, rtol=1e-13, atol=1e-13)
    knee = labels.index("th_pk")
    assert np.ptp(data[:, knee]) > 10.0  # degrees: a knee that swings, not radians


def test_gait_ground_reactions_are_the_models(gait_files, model):
    """The ground-reaction .mot, read back, is the constrained dynamics' stance-foot wrench at
    the exported state (``dyn_<d>(q, qd, u)``, q from kinematics.mot), in OpenSim's axes:
    force (F_x, F_z, 0), the centre of pressure on the ground inside the stance foot, the
    moment about it zero, so that (sole_x - px) F_z gives back the model's M_y."""
    out, gait = gait_files
    name, meta, labels, data = read_mot(out / "ground_reactions.mot")
    assert name == "GroundReactions" and meta["nColumns"] == "19" and meta["inDegrees"] == "yes"
    col = {lab: data[:, i] for i, lab in enumerate(labels)}
    for s in "rl":
        for part in ("force", "torque"):
            assert all((f"ground_{part}_{s}_v{a}" if part == "force" else
                        f"ground_{part}_{s}_{a}") in col for a in "xyz")
    _, _, _, kin = read_mot(out / "kinematics.mot")
    angle = np.array([c.startswith("th_") for c in COORDS])
    q = np.where(angle, np.radians(kin[:, 1:]), kin[:, 1:])
    qd, u = _stride(gait, "qd"), _stride(gait, "u")
    n_ps = gait.trajectory[Domain.PS]["t"].size
    fs = model.numeric()
    frames = fs["frames"]
    for k in range(data.shape[0]):
        d = Domain.PS if k < n_ps else Domain.PNS
        on, off = ("r", "l") if d is Domain.PS else ("l", "r")
        lam = np.array(fs[f"dyn_{d}"](q[k], qd[k], u[k])[1])
        fx, fz, my = lam[:3]
        assert col[f"ground_force_{on}_vx"][k] == pytest.approx(fx, abs=1e-5)
        assert col[f"ground_force_{on}_vy"][k] == pytest.approx(fz, abs=1e-5)
        assert fz > 100.0  # the stance foot carries the walker
        pose = np.array(frames(q[k], np.zeros(model.nq))[0])
        side = "p" if d is Domain.PS else "l"
        heel, toe, sole = (pose[0, model.frame_index(f"{side}_{f}")]
                           for f in ("heel", "toe", "sole"))
        px = col[f"ground_force_{on}_px"][k]
        assert heel - 1e-6 <= px <= toe + 1e-6
        # the sole's height: on the ground, within the collocation's tolerance (0.1 mm)
        z = pose[1, model.frame_index(f"{side}_sole")]
        assert col[f"ground_force_{on}_py"][k] == pytest.approx(z, abs=1e-9)
        assert abs(z) < 1e-4
        assert (sole - px) * fz == pytest.approx(my, abs=1e-4)
        assert col[f"ground_torque_{on}_z"][k] == pytest.approx(0.0, abs=1e-9)
        assert all(col[f"ground_force_{off}_{c}"][k] == 0.0
                   for c in ("vx", "vy", "vz", "px", "py", "pz"))


def test_gait_csv_forces_and_socket(gait_files, model):
    """The CSV's ground reactions are lam's foot rows in the model's axes and its socket force
    the model's eq. (Fsocket), ``socket_<d>(q, qd, u, lam_foot)``."""
    out, gait = gait_files
    header, rows = read_csv(out / "stride.csv")
    q, qd, u, lam = (_stride(gait, f) for f in ("q", "qd", "u", "lam"))
    n_ps = gait.trajectory[Domain.PS]["t"].size
    fs = model.numeric()
    ps = slice(0, n_ps)
    np.testing.assert_array_equal(column(header, rows, "p_foot_Fz [N]")[ps], lam[ps, 1])
    np.testing.assert_array_equal(column(header, rows, "l_foot_My [N m]")[n_ps:], lam[n_ps:, 2])
    assert np.all(column(header, rows, "l_foot_Fz [N]")[ps] == 0.0)
    assert np.all(np.isnan(column(header, rows, "l_foot_cop_x [m]")[ps]))  # empty cells
    for k in (0, 20, n_ps - 1, n_ps + 20):
        d = Domain.PS if k < n_ps else Domain.PNS
        f_s = np.array(fs[f"socket_{d}"](q[k], qd[k], u[k], lam[k, :3])[0])
        got = [column(header, rows, f"socket_{c}")[k] for c in ("Fx [N]", "Fz [N]", "My [N m]")]
        np.testing.assert_allclose(got, f_s, atol=1e-5)


def test_gait_without_wrenches_or_trajectory(tmp_path, capsys):
    """A gait that stores no ``lam``: the angles and no ground reactions; one without a
    trajectory: a one-line error naming the field, exit 2, nothing written."""
    doc = json.loads(DEMO.read_text())
    for d in PAPER_DOMAINS:
        del doc["trajectory"][d]["lam"]
    g = tmp_path / "no_lam.json"
    g.write_text(json.dumps(doc))
    capsys.readouterr()
    assert main(["gait", "export", str(g), "--out", str(tmp_path / "a")]) == 0
    assert "no ground reactions" in capsys.readouterr().out
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["kinematics.mot",
                                                                   "stride.csv"]
    header, _ = read_csv(tmp_path / "a" / "stride.csv")
    assert "th_pk_torque [N m]" in header and "p_foot_Fz [N]" not in header
    doc["trajectory"] = {}
    g.write_text(json.dumps(doc))
    assert main(["gait", "export", str(g), "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"field 'trajectory.{Domain.PS}': missing" in err
    assert not (tmp_path / "b").exists()
    assert main(["gait", "export", str(tmp_path / "none.json"), "--out",
                 str(tmp_path / "c")]) == 2
    assert "none.json: no such file" in capsys.readouterr().err


# ------------------------------------------------------------------------------- a run


@pytest.fixture(scope="module")
def recording(tmp_path_factory, model, template_gait):
    """A short run (clfqp, 2 steps, in process) recorded by the recorder the co-simulation
    uses (``GroundTruthRecorder``: /ground_truth and /controller/clf), with the gear ratios
    in its metadata as ``hpcosim run`` writes them."""
    from bus_schemas.recording.recorder import Recorder
    from orchestrator.loop import ControllerLink, SimulatorPlant, run_loop
    from orchestrator.loop.recorder import GroundTruthRecorder
    from prosthesis_controller import make_controller
    from tests.controller_support import tube_about_nominal
    from tests.fmu_support import simulator, start_state

    tube = tube_about_nominal(template_gait, (40.0, 60.0, 8.0))
    plant = SimulatorPlant(simulator(model, template_gait), *start_state(template_gait))
    link = ControllerLink(make_controller("clfqp", template_gait, tube, model), quantize=True)
    p = model.device.prosthesis
    ratio = (p.knee.gear_ratio.value, p.ankle.gear_ratio.value)
    path = tmp_path_factory.mktemp("run") / "run.mcap"
    with Recorder(path) as rec:
        rec.register_all()
        rec.add_metadata("device", {"gear_ratio_knee": ratio[0],
                                    "gear_ratio_ankle": ratio[1]})
        log = run_loop(plant, link, steps=2, recorder=GroundTruthRecorder(rec))
    assert log.steps == 2 and log.fall is None
    return path, ratio


def test_recording_csv_is_the_recorded_channels(recording, tmp_path):
    from bus_schemas.recording.reader import read_messages

    path, ratio = recording
    out, mot = tmp_path / "run.csv", tmp_path / "run.mot"
    assert main(["recording", "export", str(path), "--out", str(out), "--mot", str(mot)]) == 0
    gt = [o for _, _, o in read_messages(path, ["/ground_truth"])]
    clf = {o["t"]: o for _, _, o in read_messages(path, ["/controller/clf"])}
    header, rows = read_csv(out)
    assert len(rows) == len(gt) > 500
    for name in ("time [s]", "tau [1]", "th_pk [rad]", "x_B [m]", "socket_Fz [N]",
                 "socket_My [N m]", "knee_motor [N m motor]", "knee_torque [N m]", "V [1]",
                 "rho [1]"):
        assert name in header, name
    assert [r[header.index("domain")] for r in rows] == [o["domain"] for o in gt]
    assert {r[header.index("domain")] for r in rows} == {d.value for d in PAPER_DOMAINS}
    np.testing.assert_array_equal(column(header, rows, "time [s]"), [o["t"] for o in gt])
    np.testing.assert_array_equal(column(header, rows, "step"), [o["step"] for o in gt])
    for i, c in enumerate(COORDS):
        unit = "m" if c in ("x_B", "z_B", "x_f", "z_f") else "rad"
        np.testing.assert_array_equal(column(header, rows, f"{c} [{unit}]"),
                                      [o["q"][i] for o in gt])
    np.testing.assert_array_equal(column(header, rows, "socket_Fx [N]"),
                                  [o["socket_force"]["Fx"] for o in gt])
    motor = np.array([o["u_applied"] for o in gt])
    np.testing.assert_array_equal(column(header, rows, "ankle_motor [N m motor]"), motor[:, 1])
    np.testing.assert_allclose(column(header, rows, "knee_torque [N m]"), ratio[0] * motor[:, 0])
    V = column(header, rows, "V [1]")
    np.testing.assert_array_equal(V, [clf[o["t"]]["V"] for o in gt])
    assert np.isfinite(V).all() and (V >= 0).all()  # clfqp reports its CLF every period
    # the .mot: the same coordinates, angles in degrees
    name, meta, labels, data = read_mot(mot)
    assert meta["inDegrees"] == "yes" and labels == ["time", *COORDS]
    assert int(meta["nRows"]) == len(gt)
    i = COORDS.index("th_lk")
    np.testing.assert_allclose(data[:, 1 + i], np.degrees([o["q"][i] for o in gt]),
                               rtol=1e-13)


@pytest.mark.slow
def test_recording_export_of_a_cosimulation(tmp_path_factory, tmp_path, model, template_gait):
    """A real ``hpcosim run`` recording (FMU, controller process over zenoh, one step): every
    /ground_truth row exported, the joint torques from the gear ratios the run recorded."""
    from bus_schemas.recording.reader import read_messages
    from hp_model.force_tube import save_tube
    from orchestrator.cosim.config import CosimConfig
    from orchestrator.cosim.master import run_cosim
    from tests.controller_support import tube_about_nominal
    from tests.fmu_support import built_fmu

    fmu, gait = built_fmu(tmp_path_factory, model, template_gait)
    tube = tmp_path / "tube.json"
    save_tube(tube, tube_about_nominal(template_gait, (0.1, 0.15, 0.02)))
    rec = tmp_path / "run.mcap"
    res = run_cosim(CosimConfig(controller="clfqp", gait=gait, tube=tube, fmu=fmu, steps=1,
                                record=rec), model=model)
    assert res.steps == 1 and not res.fell
    out = tmp_path / "run.csv"
    assert main(["recording", "export", str(rec), "--out", str(out)]) == 0
    header, rows = read_csv(out)
    gt = [o for _, _, o in read_messages(rec, ["/ground_truth"])]
    assert len(rows) == len(gt) == res.ticks
    ratio = model.device.prosthesis.ankle.gear_ratio.value
    np.testing.assert_allclose(column(header, rows, "ankle_torque [N m]"),
                               ratio * np.array([o["u_applied"][1] for o in gt]))
    assert np.isfinite(column(header, rows, "rho [1]")).all()


def test_recording_export_errors(tmp_path, capsys):
    """An empty recording, a file that is not one, a missing file: one line, exit 2, no
    CSV."""
    from bus_schemas.recording.recorder import Recorder

    empty = tmp_path / "empty.mcap"
    with Recorder(empty) as rec:
        rec.register_all()
    junk = tmp_path / "junk.mcap"
    junk.write_text("not mcap")
    out = tmp_path / "x.csv"
    capsys.readouterr()
    for src, says in ((empty, "0 /ground_truth messages"), (junk, "not a readable MCAP"),
                      (tmp_path / "none.mcap", "none.mcap: no such file")):
        assert main(["recording", "export", str(src), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and says in err, err
        assert not out.exists()


def test_recording_angles_are_the_models(model):
    """Which columns the recording export converts to degrees: the model's angles."""
    from characterization.gait.export import angle_flags
    from orchestrator.cosim.export import ANGLES

    assert tuple(angle_flags(model)) == ANGLES
    assert sum(ANGLES) == 8  # th_B, th_f, the 6 joints; x_B, z_B, x_f, z_f in m


# ------------------------------------------------------------------------------- the writer


def test_tables_round_trip_and_refuse_what_opensim_refuses():
    x = np.array([0.1, 1 / 3, -2.5e-17, np.nan])
    text = csv_text([Column("a", "rad", x), Column("w", None, ["ps", "pns", "", "x"]),
                     Column("n", None, [1, None, 3, 4])])
    rows = list(csv.reader(text.splitlines()))
    assert rows[0] == ["a [rad]", "w", "n"]
    assert [float(r[0]) for r in rows[1:4]] == list(x[:3])  # bit for bit
    assert rows[4][0] == "" and rows[2][2] == ""
    with pytest.raises(TableError, match="different lengths"):
        csv_text([Column("a", None, [1]), Column("b", None, [1, 2])])
    ok = MotTable("T", np.array([0.0, 0.1]), ("a",), np.array([[1.0], [2.0]]), True)
    assert mot_text(ok).startswith("T\nversion=1\nnRows=2\nnColumns=2\ninDegrees=yes\n")
    for bad, says in (((np.array([0.0, 0.0]), ("a",)), "does not increase"),
                      ((np.array([0.0, 0.1]), ("time",)), "unique and not 'time'"),
                      ((np.array([0.0, 0.1]), ("a b",)), "blank")):
        with pytest.raises(TableError, match=says):
            mot_text(MotTable("T", bad[0], bad[1], np.array([[1.0], [2.0]]), True))
