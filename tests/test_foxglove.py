"""Foxglove (issue 21): a short lockstep co-simulation's recording carries the walker as
Foxglove's published schemas (the ``foxglove-schemas-protobuf`` package) read them, its
transforms are a tree rooted at ``world`` that agrees with the model's forward kinematics,
and the shipped layout names only topics and message paths the recording has."""

from __future__ import annotations

import contextlib
import json
import math
import re
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from google.protobuf import descriptor_pool
from google.protobuf.descriptor_pb2 import FileDescriptorProto, FileDescriptorSet
from google.protobuf.unknown_fields import UnknownFieldSet
from mcap.reader import make_reader

from bus_schemas.recording.reader import read_messages
from bus_schemas.recording.schemas import FOXGLOVE_CHANNELS
from hp_model.force_tube import save_tube
from orchestrator.cosim.config import CosimConfig
from orchestrator.cosim.master import run_cosim
from orchestrator.loop.foxglove import PERIOD, WORLD
from orchestrator.loop.walker_figure import FORCE_SCALE
from tests.controller_support import tube_about_nominal
from tests.fmu_support import built_fmu

ROOT = Path(__file__).resolve().parents[1]
LAYOUT = ROOT / "foxglove" / "hpcosim-layout.json"


def published(name: str) -> type:
    """The class of Foxglove message ``name`` as the schema package publishes it."""
    import importlib

    short = name.split(".")[1]
    return getattr(importlib.import_module(f"foxglove_schemas_protobuf.{short}_pb2"), short)


@pytest.fixture(scope="module")
def recording(tmp_path_factory, model, template_gait):
    fmu, gait = built_fmu(tmp_path_factory, model, template_gait)
    d = tmp_path_factory.mktemp("foxglove")
    tube = d / "tube.json"
    save_tube(tube, tube_about_nominal(template_gait, (0.1, 0.15, 0.02)))
    rec = d / "run.mcap"
    res = run_cosim(CosimConfig(controller="clfqp", gait=gait, tube=tube, fmu=fmu, steps=3,
                                record=rec), model=model)
    assert not res.faulted and not res.fell and res.steps == 3, res
    by: dict[str, list] = defaultdict(list)
    with open(rec, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        for _, ch, msg in reader.iter_messages():
            by[ch.topic].append((msg.log_time, msg.data))
    return rec, summary, by, res


def unknown_fields(msg) -> int:
    """Fields of ``msg`` and its sub-messages that its schema does not define."""
    n = len(UnknownFieldSet(msg))
    for fd, v in msg.ListFields():
        if fd.message_type is not None:
            for m in (v if fd.is_repeated else [v]):
                n += unknown_fields(m)
    return n


def test_foxglove_channels_use_the_published_schemas(recording):
    """Each /walker/* channel: protobuf, its schema record the package's own descriptors,
    and every message parses with the package's class, nothing unknown, byte for byte."""
    _, summary, by, res = recording
    chans = {c.topic: c for c in summary.channels.values()}
    pool = descriptor_pool.Default()
    for topic, name in FOXGLOVE_CHANNELS.items():
        ch = chans[topic]
        schema = summary.schemas[ch.schema_id]
        assert (ch.message_encoding, schema.encoding, schema.name) == ("protobuf", "protobuf",
                                                                        name)
        cls = published(name)
        files = FileDescriptorSet.FromString(schema.data).file
        assert cls.DESCRIPTOR.file.name in {f.name for f in files}
        for f in files:  # each file as the package (and protobuf) publish it
            ref = FileDescriptorProto()
            pool.FindFileByName(f.name).CopyToProto(ref)
            assert f == ref, f.name
        msgs = by[topic]
        assert len(msgs) == pytest.approx(res.sim_time / PERIOD, abs=2)
        for ns, data in msgs:
            m = cls.FromString(data)
            assert unknown_fields(m) == 0 and m.SerializeToString() == data
            stamps = ([t.timestamp for t in m.transforms] if topic == "/walker/tf"
                      else [e.timestamp for e in m.entities])
            assert stamps and all(s.seconds * 10**9 + s.nanos == ns for s in stamps)


def _transforms(by) -> list[tuple[int, object]]:
    cls = published("foxglove.FrameTransforms")
    return [(ns, cls.FromString(d)) for ns, d in by["/walker/tf"]]


def _rotate(q, v):
    """Vector ``v`` rotated by unit quaternion ``q`` (x, y, z, w)."""
    u, w = np.array(q[:3]), q[3]
    v = np.asarray(v, float)
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


def _world(tfs) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """World (position, quaternion) of every child frame, composing up the tree."""
    local = {t.child_frame_id: (t.parent_frame_id,
                                np.array([t.translation.x, t.translation.y, t.translation.z]),
                                np.array([t.rotation.x, t.rotation.y, t.rotation.z,
                                          t.rotation.w])) for t in tfs}
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {WORLD: (np.zeros(3),
                                                             np.array([0, 0, 0, 1.0]))}

    def pose(frame: str, depth: int = 0):
        assert depth <= len(local), f"a cycle through {frame}"
        if frame not in out:
            parent, p, q = local[frame]
            pp, pq = pose(parent, depth + 1)
            x1, y1, z1, w1 = pq
            x2, y2, z2, w2 = q
            out[frame] = (pp + _rotate(pq, p),
                          np.array([w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                                    w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                                    w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
                                    w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2]))
        return out[frame]

    for child in local:
        pose(child)
    return out


def test_transforms_are_a_tree_that_agrees_with_the_model(recording, model):
    """Every model frame is one child with one parent, all reach ``world``; composed to
    world at a sample they are where the model's forward kinematics puts them (1e-9 m),
    pitched about +y; a frame on its parent's body sits at the body offset at all times."""
    rec, _, by, _ = recording
    tfs = _transforms(by)
    names = set(model.frame_names)
    tree = {f.name: f for f in model.tree.frames}
    for _, m in tfs:
        children = [t.child_frame_id for t in m.transforms]
        assert sorted(children) == sorted(names)  # each frame once
        for t in m.transforms:
            assert t.parent_frame_id in names | {WORLD}
            assert math.isclose(np.linalg.norm([t.rotation.x, t.rotation.y, t.rotation.z,
                                                t.rotation.w]), 1.0, abs_tol=1e-12)
            assert t.rotation.x == t.rotation.z == t.translation.y == 0.0  # planar
            parent = tree.get(t.parent_frame_id)
            if parent is not None and parent.body == tree[t.child_frame_id].body:
                off = np.subtract(tree[t.child_frame_id].point, parent.point)
                assert [t.translation.x, t.translation.z] == pytest.approx(off, abs=1e-12)
                assert t.rotation.w == pytest.approx(1.0, abs=1e-12)
    assert sum(t.parent_frame_id == WORLD for t in tfs[0][1].transforms) == 1
    assert any(tree[t.child_frame_id].body == tree[t.parent_frame_id].body
               for t in tfs[0][1].transforms if t.parent_frame_id != WORLD)
    truth = {ns: o for _, ns, o in read_messages(rec, ["/ground_truth"])}
    ns, m = tfs[len(tfs) // 2]
    q = np.array(truth[ns]["q"], float)
    pose = np.asarray(model.numeric()["frames"](q, np.zeros(model.nq))[0])
    world = _world(m.transforms)
    for j, name in enumerate(model.frame_names):
        p, quat = world[name]
        assert p == pytest.approx([pose[0, j], 0.0, pose[1, j]], abs=1e-9), name
        x_axis = _rotate(quat, [1.0, 0.0, 0.0])  # pitch th turns +x to (cos th, 0, -sin th)
        assert x_axis == pytest.approx([math.cos(pose[2, j]), 0.0, -math.sin(pose[2, j])],
                                       abs=1e-9)


def test_scene_draws_the_walker_where_the_model_is(recording, model):
    """The scene at a stance sample: spheres at every frame, human and prosthesis in
    different colours, the ground, the socket force as an arrow of |F| / FORCE_SCALE m
    along the force turned to world."""
    rec, _, by, _ = recording
    cls = published("foxglove.SceneUpdate")
    truth = {ns: o for _, ns, o in read_messages(rec, ["/ground_truth"])}
    ns, data = next((ns, d) for ns, d in by["/walker/scene"][5:]
                    if truth[ns]["domain"] == "ps")
    m = cls.FromString(data)
    ents = {e.id: e for e in m.entities}
    assert set(ents) == {"walker", "ground"} and all(e.frame_id == WORLD for e in m.entities)
    g = ents["ground"].cubes[0]
    assert g.pose.position.z + g.size.z / 2 == pytest.approx(0.0, abs=1e-12)
    w = ents["walker"]
    q = np.array(truth[ns]["q"], float)
    pose = np.asarray(model.numeric()["frames"](q, np.zeros(model.nq))[0])
    centres = [(s.pose.position.x, s.pose.position.z) for s in w.spheres]
    colour = {}
    for j, name in enumerate(model.frame_names):
        k = centres.index(pytest.approx((pose[0, j], pose[1, j]), abs=1e-9))
        c = w.spheres[k].color
        colour[name] = (c.r, c.g, c.b)
    assert colour["p_knee"] == colour["socket"] != colour["l_knee"] == colour["hip"]
    (arrow,) = w.arrows
    f = truth[ns]["socket_force"]
    a = pose[2, model.frame_names.index("socket")]
    world_f = np.array([math.cos(a) * f["Fx"] + math.sin(a) * f["Fz"],
                        -math.sin(a) * f["Fx"] + math.cos(a) * f["Fz"]])
    o = arrow.pose.orientation
    direction = _rotate([o.x, o.y, o.z, o.w], [1.0, 0.0, 0.0])
    assert direction[[0, 2]] == pytest.approx(world_f / np.linalg.norm(world_f), abs=1e-9)
    assert arrow.shaft_length + arrow.head_length == pytest.approx(
        np.linalg.norm(world_f) / FORCE_SCALE, rel=1e-12)
    assert len(w.lines) >= 4 and len({(ln.color.r, ln.color.b) for ln in w.lines}) >= 2


# --------------------------------------------------------------------------- layout


def _panels(node) -> list[str]:
    if isinstance(node, str):
        return [node]
    return _panels(node["first"]) + _panels(node["second"])


_STEP = re.compile(r"\.([A-Za-z_]\w*)|\[(\d+)\]")


def _resolve(obj, rest: str):
    """The value at message path ``rest`` (``.field`` and ``[i]`` steps) of a decoded JSON
    message (None below a null: the tube's bounds outside ps); KeyError/IndexError if it
    has none."""
    pos = 0
    while pos < len(rest) and obj is not None:
        m = _STEP.match(rest, pos)
        assert m, f"unparsed message path {rest[pos:]!r}"
        obj = obj[m.group(1)] if m.group(1) else obj[int(m.group(2))]
        pos = m.end()
    return obj


def test_layout_parses_and_names_what_recordings_have(recording, model):
    rec, summary, by, _ = recording
    doc = json.loads(LAYOUT.read_text())
    cfg = doc["configById"]
    assert sorted(_panels(doc["layout"])) == sorted(cfg)
    kinds = {pid.split("!")[0] for pid in cfg}
    assert {"3D", "Plot", "StateTransitions", "SourceInfo"} <= kinds
    topics = {c.topic for c in summary.channels.values()}
    three_d = cfg["3D!walker"]
    assert set(three_d["topics"]) == set(FOXGLOVE_CHANNELS) <= topics
    assert three_d["followTf"] in model.frame_names
    paths = [s["value"] for pid, c in cfg.items() if pid.split("!")[0] in
             ("Plot", "StateTransitions") for s in c["paths"]]
    assert len(paths) >= 20
    decoded: dict[str, list] = {}
    for path in paths:
        topic = max((t for t in topics if path.startswith(t + ".")), key=len, default=None)
        assert topic is not None, f"{path}: no such topic in the recording"
        if topic not in decoded:
            decoded[topic] = [o for _, _, o in read_messages(rec, [topic])]
        values = []
        for o in decoded[topic]:
            with contextlib.suppress(KeyError, IndexError):
                values.append(_resolve(o, path[len(topic):]))
        assert values, f"{path}: in no message of {topic}"
        assert all(v is None or isinstance(v, int | float | str) for v in values), path
        assert any(isinstance(v, int | float | str) for v in values), f"{path}: all null"
    # the panels cover what issue 21 lists
    for needed in ("/walker/reference.knee", "/walker/reference.ankle",
                   "/prosthesis/torque_command.knee_joint", "/ground_truth.socket_force.Fz",
                   "/walker/reference.socket_lower.Fz", "/controller/clf.V",
                   "/controller/clf.rho", "/can/rates.rx.TorqueCmd", "/can/rates.rx.CtrlClf"):
        assert needed in paths
    assert len(by["/can/rates"]) >= 5
    # V and rho: one record per period, none null (clfqp relaxes: rho is present)
    clf = [o for _, _, o in read_messages(rec, ["/controller/clf"])]
    assert len(clf) == summary.statistics.channel_message_counts[next(
        i for i, c in summary.channels.items() if c.topic == "/ground_truth")]
    assert all(o["V"] is not None and o["rho"] is not None for o in clf)


def test_reference_is_the_gait_and_the_tube_at_the_recorded_phase(recording, model,
                                                                   template_gait):
    """/walker/reference: the desired knee as the scenarios' knee reference, the ankle
    only in pns, the socket-force bounds the tube's box (c -/+ r) in ps."""
    from hp_model.force_tube import load_tube
    from orchestrator.cosim.recording import read_recording
    from orchestrator.experiments.scenarios import knee_reference

    rec, _, _, _ = recording
    rows = [o for _, _, o in read_messages(rec, ["/walker/reference"])]
    tube_path = rec.parent / "tube.json"
    assert read_recording(rec, messages=False).attachments["tube.json"] == \
        tube_path.read_bytes()
    tube = load_tube(tube_path, template_gait.hash())
    code = np.array([0 if o["domain"] == "ps" else 1 for o in rows])
    tau = np.array([o["tau"] for o in rows])
    assert {0, 1} <= set(code.tolist())
    assert [o["knee"] for o in rows] == pytest.approx(
        knee_reference(template_gait, code, tau), abs=1e-12)
    for o in rows:
        assert (o["ankle"] is None) == (o["domain"] == "ps")
        if o["domain"] == "ps":
            c, r = tube.box(o["tau"])
            assert [o["socket_lower"][k] for k in ("Fx", "Fz", "My")] == pytest.approx(
                c - r, abs=1e-9)
            assert [o["socket_upper"][k] for k in ("Fx", "Fz", "My")] == pytest.approx(
                c + r, abs=1e-9)
        else:
            assert o["socket_lower"] is None and o["socket_upper"] is None
