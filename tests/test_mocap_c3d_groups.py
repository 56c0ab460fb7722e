"""C3D files as Vicon Nexus writes a processed trial (issue 40): the model's outputs stored as
points (POINT:ANGLES, FORCES, MOMENTS, POWERS, SCALARS, REACTIONS, MODELED_MARKERS and the
unnamed bones) are not markers, and the file's up axis (POINT:Y_SCREEN) is the up guess.

The files are written here with ezc3d directly (not with the project's writer): the
synthetic subject's markers in mm, then the outputs in their own units, as Nexus orders
them.  A hip moment in N mm spans tens of "metres" along the lab's x: read as a marker it
made the up guess +x and the mapping skeleton take it for the right thigh.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from characterization.mocap.c3d_io import read_c3d, write_c3d
from characterization.mocap.inspection import TODO, mapping_skeleton, summarize
from characterization.mocap.mapping import default_mapping
from characterization.mocap.pipeline import process_take
from characterization.mocap.synthetic_subject import SynthOptions, synthesize
from characterization.mocap.take import MocapError, Take
from orchestrator.cli import main

#: POINT group -> the unit parameter Nexus writes beside it, and its value
UNIT_PARAMS = {"ANGLES": ("ANGLE_UNITS", "deg"), "FORCES": ("FORCE_UNITS", "N"),
               "MOMENTS": ("MOMENT_UNITS", "Nmm"), "POWERS": ("POWER_UNITS", "W"),
               "SCALARS": ("SCALAR_UNITS", "mm"), "REACTIONS": ("REACTION_UNITS", "N"),
               "MODELED_MARKERS": ("MODELED_MARKER_UNITS", "mm")}
#: Nexus's POINT:TYPE_GROUPS (each group with its singular twin)
TYPE_GROUPS = ["ANGLES", "ANGLE", "FORCES", "FORCE", "MOMENTS", "MOMENT", "POWERS", "POWER",
               "SCALARS", "SCALAR", "MODELED_MARKERS", "MODELED_MARKER", "REACTIONS",
               "REACTION"]
LOST = 4  # frames at the start without kinetics (Nexus: the filter's edge)


@pytest.fixture(scope="module")
def synth(model):
    return synthesize(model, SynthOptions(n_strides=4, seed=5))


def outputs_of(take: Take) -> dict[str, tuple[str, np.ndarray]]:
    """Model outputs in their file units, name -> (kind, (n, 3)), shaped like Nexus's."""
    n = take.n_frames
    ph = 2 * np.pi * np.arange(n) / 137.0  # about one stride
    hat = take.markers["HAT:Marker1"] * 1000.0
    z = np.zeros(n)
    kinetic = {  # NaN for the first frames, as Nexus leaves them
        "RHipMoment": ("MOMENTS", np.column_stack([80000 * np.sin(ph), 9000 * np.cos(ph), z])),
        "RKneeForce": ("FORCES", np.column_stack([0.2 * np.sin(ph), 0.1 * z, 1.1 + 0 * z])),
        "RHipPower": ("POWERS", np.column_stack([z, z, 1.2 * np.sin(ph)])),
        "LGroundReaction": ("REACTIONS", np.column_stack([z, 40 * np.sin(ph),
                                                          800 * np.maximum(np.sin(ph), 0)])),
    }
    for _, v in kinetic.values():
        v[:LOST] = np.nan
    out = {
        "LKneeAngles": ("ANGLES", np.column_stack([30 + 30 * np.sin(ph), -5 + z, 3 + z])),
        "RAnkleAngles": ("ANGLES", np.column_stack([10 * np.cos(ph), z, z])),
        "LArchHeightIndex": ("SCALARS", np.column_stack([z, z, 20 + z])),
        "LHJC": ("MODELED_MARKERS", take.markers["LThigh:Marker1"] * 1000.0 + [0, 80, 90]),
        **kinetic,
    }
    for suffix, off in zip("OALP", ([0, 0, 0], [100, 0, 0], [0, 100, 0], [0, 0, 100]),
                           strict=True):  # the pelvis bone: no POINT group names it
        out["PEL" + suffix] = ("BONES", hat + off)
    return out


def write_vicon(path: Path, take: Take, outputs: dict[str, tuple[str, np.ndarray]],
                y_screen: str | None = "+Z") -> Path:
    """``take``'s markers (mm) and ``outputs`` as Nexus writes a processed C3D."""
    import ezc3d

    names = [*take.markers, *outputs]
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [float(take.frame_rate)]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(names)
    c.add_parameter("POINT", "UNITS", ["mm"])
    if y_screen is not None:
        c.add_parameter("POINT", "X_SCREEN", ["+X"])
        c.add_parameter("POINT", "Y_SCREEN", [y_screen])
    values = [take.markers[k] * 1000.0 for k in take.markers] + [v for _, v in outputs.values()]
    pts = np.ones((4, len(names), take.n_frames))
    for i, v in enumerate(values):
        pts[:3, i, :] = v.T
        pts[:, i, ~np.all(np.isfinite(v), axis=1)] = np.nan
    c["data"]["points"] = pts
    groups: dict[str, list[str]] = {}
    for name, (kind, _) in outputs.items():
        groups.setdefault(kind, []).append(name)
    for kind, labels in groups.items():
        if kind in UNIT_PARAMS:
            c.add_parameter("POINT", kind, labels)
            unit_param, unit = UNIT_PARAMS[kind]
            c.add_parameter("POINT", unit_param, [unit])
    c.add_parameter("POINT", "TYPE_GROUPS", TYPE_GROUPS)
    c.write(str(path))
    return path


@pytest.fixture(scope="module")
def vicon(synth, tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("vicon")
    return write_vicon(d / "processed.c3d", synth.take_c3d, outputs_of(synth.take_c3d))


def _skeleton_names(text: str) -> set[str]:
    """The names the skeleton puts in the mapping (not in its comments)."""
    body = "\n".join(x.split("#")[0] for x in text.splitlines())
    return set(re.findall(r'"([^"]+)"', body)) - {"+x", "-x", "+y", "-y", "+z", "-z", "auto",
                                                  "forward", TODO}


def test_model_outputs_are_not_markers(synth, vicon) -> None:
    """The markers are the subject's, as a plain C3D gives them; every output is a model
    output of its group's kind, in the file's units, NaN where Nexus left none; the bones
    (PELO/PELA/PELL/PELP, in no group) too; the up axis is the file's POINT:Y_SCREEN."""
    take = read_c3d(vicon)
    ref = synth.take_c3d
    assert list(take.markers) == list(ref.markers)
    for k, v in ref.markers.items():
        np.testing.assert_allclose(take.markers[k], v, atol=2e-6, rtol=0)  # float32 in mm
    want = outputs_of(ref)
    assert set(take.model_outputs) == set(want)
    for name, (kind, v) in want.items():
        o = take.model_outputs[name]
        unit = "mm" if kind == "BONES" else UNIT_PARAMS[kind][1]
        assert (o.kind, o.unit) == (kind, unit), name
        np.testing.assert_allclose(o.values, v, rtol=1e-6, atol=2e-3)  # as the file has it
    assert np.isnan(take.model_outputs["RHipMoment"].values[:LOST]).all()
    assert np.isfinite(take.model_outputs["RHipMoment"].values[LOST:]).all()
    assert (take.up_axis, take.up_axis_source) == ("+z", "POINT:Y_SCREEN")
    with pytest.raises(MocapError, match=r"processed.c3d: 'RHipMoment' is not a marker: the "
                       r"lab's model computed it \(POINT:MOMENTS\)"):
        take.marker("RHipMoment")


def test_without_type_groups_the_known_groups_still_name_the_outputs(synth, tmp_path) -> None:
    """A file without POINT:TYPE_GROUPS: the groups the C3D world uses (ANGLES, FORCES,
    MOMENTS, POWERS, SCALARS, REACTIONS, MODELED_MARKERS) still name the outputs; a raw
    file (no group) has no model outputs, and a four-letter family ending O/A/L/P there is
    taken for markers (bones are only looked for in a processed file)."""
    import ezc3d

    path = write_vicon(tmp_path / "v.c3d", synth.take_c3d, outputs_of(synth.take_c3d))
    c = ezc3d.c3d(str(path))
    par = dict(c["parameters"]["POINT"])
    del par["TYPE_GROUPS"]
    from characterization.mocap.c3d_io import take_from_c3d

    take = take_from_c3d({"parameters": {"POINT": par}, "data": c["data"],
                          "header": c["header"]}, "v.c3d")
    assert set(take.model_outputs) == set(outputs_of(synth.take_c3d))
    bones = {k: v for k, v in outputs_of(synth.take_c3d).items() if v[0] == "BONES"}
    raw = read_c3d(write_vicon(tmp_path / "raw.c3d", synth.take_c3d, bones))
    assert raw.model_outputs == {} and set(bones) <= set(raw.markers)


def test_inspect_lists_and_maps_only_markers_and_takes_the_files_up(synth, vicon,
                                                                   capsys) -> None:
    """``mocap inspect``: the columns are the markers, the outputs are counted apart, up is
    +z from the file; the skeleton names only markers (before: r_thigh = RHipMoment, up
    +x from the moment's tens of "metres")."""
    take = read_c3d(vicon)
    s = summarize(take)
    assert [c.name for c in s.columns] == list(synth.take_c3d.markers)
    assert {c.kind for c in s.columns} == {"marker"}
    assert s.up_axis == "+z" and "POINT:Y_SCREEN" in s.up_reason
    assert 1.0 < s.up_span < 2.0  # a person, not a moment in N mm
    assert dict(s.model_outputs) == {"ANGLES": 2, "SCALARS": 1, "MODELED_MARKERS": 1,
                                     "MOMENTS": 1, "FORCES": 1, "POWERS": 1, "REACTIONS": 1,
                                     "BONES": 4}
    text = mapping_skeleton(take)
    names = _skeleton_names(text)
    assert names and names <= set(take.markers), names - set(take.markers)
    assert 'up = "+z"' in text
    assert main(["mocap", "inspect", str(vicon)]) == 0
    out = capsys.readouterr().out
    rows = [x for x in out.splitlines() if x.startswith("│ marker")]
    assert len(rows) == len(take.markers)
    assert not any(o in r for r in rows for o in take.model_outputs)
    assert "up +z" in out and "POINT:Y_SCREEN" in out
    assert "model outputs (not markers): 2 ANGLES, 1 SCALARS" in out


def test_the_files_up_axis_is_honoured(synth, tmp_path) -> None:
    """A Y-up lab saying so (POINT:Y_SCREEN "+Y") is read +y, not C3D's +z; without the
    parameter the format's +z stays the take's axis and inspect guesses from the span; a
    file whose word disagrees with the markers' span keeps the file's and says so."""
    ref = synth.take_c3d
    rot = ref.replace(markers={k: v[:, [0, 2, 1]] * [1, 1, -1] for k, v in ref.markers.items()})
    said = read_c3d(write_vicon(tmp_path / "y.c3d", rot, {}, y_screen="+Y"))
    assert (said.up_axis, said.up_axis_source) == ("+y", "POINT:Y_SCREEN")
    assert summarize(said).up_axis == "+y"
    silent = read_c3d(write_vicon(tmp_path / "none.c3d", rot, {}, y_screen=None))
    assert (silent.up_axis, silent.up_axis_source) == ("+z", "")
    s = summarize(silent)
    assert s.up_axis == "+y" and "largest span" in s.up_reason
    wrong = summarize(read_c3d(write_vicon(tmp_path / "w.c3d", rot, {}, y_screen="+Z")))
    assert wrong.up_axis == "+z" and "span the most along y, check it" in wrong.up_reason
    for bad in ("+Q", "Z", "+X"):  # malformed, or along X_SCREEN's axis: not an up axis
        t = read_c3d(write_vicon(tmp_path / "b.c3d", ref, {}, y_screen=bad))
        assert (t.up_axis, t.up_axis_source) == ("+z", ""), bad


def test_the_outputs_change_nothing_in_the_steps(synth, vicon, coef, tmp_path) -> None:
    """Processed as a take, the file gives the same angles and steps, bit for bit, as the
    markers alone written by the project's writer (float32 in mm both)."""
    plain = tmp_path / "plain.c3d"
    write_c3d(plain, synth.take_c3d)
    a = process_take(read_c3d(plain), default_mapping(), coef)
    b = process_take(read_c3d(vicon), default_mapping(), coef)
    np.testing.assert_array_equal(a.q, b.q)
    assert [(s.domain, s.start, s.end) for s in a.steps] == \
        [(s.domain, s.start, s.end) for s in b.steps]
    assert len(a.steps) >= 6


def test_write_c3d_keeps_the_outputs_and_the_up_axis(vicon, tmp_path) -> None:
    """The project's writer round-trips a processed take: markers, model outputs (kind, unit,
    values), their groups for other readers, and the up axis."""
    import ezc3d

    take = read_c3d(vicon)
    out = tmp_path / "again.c3d"
    write_c3d(out, take)
    back = read_c3d(out)
    assert list(back.markers) == list(take.markers)
    for k, v in take.markers.items():
        np.testing.assert_allclose(back.markers[k], v, atol=2e-6, rtol=0)
    assert list(back.model_outputs) == list(take.model_outputs)
    for k, o in take.model_outputs.items():
        b = back.model_outputs[k]
        assert (b.kind, b.unit) == (o.kind, o.unit)
        np.testing.assert_array_equal(b.values, o.values)
    assert (back.up_axis, back.up_axis_source) == ("+z", "POINT:Y_SCREEN")
    par = ezc3d.c3d(str(out))["parameters"]["POINT"]
    assert [s.strip() for s in par["MOMENTS"]["value"]] == ["RHipMoment"]
    assert par["MOMENT_UNITS"]["value"] == ["Nmm"]
