"""Virtual markers (the mapping's ``[virtual_markers]``): a mean of markers frame by frame,
and the hip centre of Harrington et al. 2007 on the pelvis's midline, which in a static
trial is where the landmark calibration's own (sagittal) hip centre is; bad entries are one
line naming the entry."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from characterization.mocap.files import read_take
from characterization.mocap.mapping import MocapMapping, Pelvis, load_mapping
from characterization.mocap.pipeline import hip_centre, resolve_frame
from characterization.mocap.take import MocapError, Take
from characterization.mocap.virtual_markers import with_virtual_markers

STRIDES = Path(__file__).parent / "data" / "opensim-walk-strides"


def _take(**markers: np.ndarray) -> Take:
    n = next(iter(markers.values())).shape[0]
    return Take("t.c3d", 100.0, np.arange(n) / 100.0, markers, up_axis="+z")


def _mapping(virtual: dict) -> MocapMapping:
    return MocapMapping.model_validate({
        "limbs": {"hat": {"markers": ["A", "B"]}}, "virtual_markers": virtual})


def test_a_mean_of_markers_frame_by_frame_and_missing_where_one_is():
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    b[3] = np.nan
    take = with_virtual_markers(_take(A=a, B=b), _mapping({"MID": ["A", "B"]}))
    np.testing.assert_allclose(take.marker("MID")[[0, 1, 2, 4]], ((a + b) / 2)[[0, 1, 2, 4]])
    assert np.all(np.isnan(take.marker("MID")[3]))
    np.testing.assert_array_equal(take.marker("A"), a)  # the take's own markers unchanged


def test_a_virtual_marker_may_be_built_from_the_ones_before_it():
    a, b, c = (np.full((3, 3), v) for v in (0.0, 2.0, 5.0))
    take = with_virtual_markers(_take(A=a, B=b, C=c),
                                _mapping({"AB": ["A", "B"], "ABC": ["AB", "C"]}))
    np.testing.assert_allclose(take.marker("ABC"), np.full((3, 3), 3.0))


@pytest.mark.parametrize("feet", [True, False])
def test_hip_centre_on_a_level_pelvis_is_harringtons(feet):
    """A pelvis 0.25 m wide and 0.16 m deep, level, facing +x, z up: behind the ASIS
    midpoint by 0.24 * 160 + 9.9 mm and below it by 0.30 * 250 + 10.9 mm; "below" toward
    the feet's markers, or without any the file's down axis."""
    n = 3
    asis_l = np.tile([0.0, 0.125, 1.0], (n, 1))
    asis_r = np.tile([0.0, -0.125, 1.0], (n, 1))
    sacrum = np.tile([-0.16, 0.0, 1.0], (n, 1))
    heel = np.tile([0.0, 0.1, 0.05], (n, 1))
    take = _take(LASI=asis_l, RASI=asis_r, SACR=sacrum, LHEE=heel)
    limb = "l_foot" if feet else "hat"
    m = MocapMapping.model_validate({
        "limbs": {limb: {"markers": ["LHEE", "LHEE"]}},
        "virtual_markers": {"HJC": {"asis": ["LASI", "RASI"], "sacrum": ["SACR"]}}})
    hjc = with_virtual_markers(take, m).marker("HJC")
    expected = [-(0.24 * 160 + 9.9) / 1000, 0.0, 1.0 - (0.30 * 250 + 10.9) / 1000]
    np.testing.assert_allclose(hjc, np.tile(expected, (n, 1)), atol=1e-12)


def test_hip_centre_in_a_static_trial_is_harringtons_in_the_sagittal_plane():
    """OpenSim's subject01 standing: the frame-by-frame hip centre (3-D, along the pelvis's
    own axes), projected, is Harrington's regression worked in the sagittal plane from the
    same markers' medians within 2 mm (they differ by the pelvis's lateral tilt); the
    calibration uses that point (``hip_centre``)."""
    mapping = load_mapping(STRIDES / "mapping.toml")
    assert mapping.calibration is not None and mapping.calibration.pelvis is not None
    pelvis = mapping.calibration.pelvis
    static = read_take(STRIDES / "subject01_static.trc")
    frame = resolve_frame(static, mapping)
    track = with_virtual_markers(
        static, mapping.model_copy(update={"virtual_markers": {"HJC": pelvis}})).marker("HJC")
    ours = np.nanmedian(frame.project(track), axis=0)
    med = {n: frame.project(np.nanmedian(static.marker(n), axis=0)[None, :])[0]
           for n in (*pelvis.asis, *pelvis.sacrum)}
    lab = {n: np.nanmedian(static.marker(n), axis=0) for n in med}
    mid = (med[pelvis.asis[0]] + med[pelvis.asis[1]]) / 2
    sacrum = np.mean([med[n] for n in pelvis.sacrum], axis=0)
    width = 1000 * np.linalg.norm(lab[pelvis.asis[0]] - lab[pelvis.asis[1]])
    depth = 1000 * np.linalg.norm((lab[pelvis.asis[0]] + lab[pelvis.asis[1]]) / 2
                                  - np.mean([lab[n] for n in pelvis.sacrum], axis=0))
    fwd = (mid - sacrum) / np.linalg.norm(mid - sacrum)
    up = np.array([-fwd[1], fwd[0]]) * np.sign(fwd[0])
    expected = mid - (0.24 * depth + 9.9) / 1000 * fwd - (0.30 * width + 10.9) / 1000 * up
    np.testing.assert_allclose(ours, expected, atol=0.002)
    np.testing.assert_allclose(hip_centre(static, frame, mapping, pelvis), ours, atol=1e-9)


@pytest.mark.parametrize(("virtual", "words"), [
    ({"MID": ["A", "NOPE"]}, ["no marker column 'NOPE'", "virtual_markers.MID"]),
    ({"A": ["A", "B"]}, ["virtual_markers.A", "already has a marker 'A'"]),
    ({"HJC": Pelvis(asis=("A", "B"), sacrum=["C"])}, ["no marker column 'C'",
                                                       "virtual_markers.HJC"]),
])
def test_a_bad_virtual_marker_is_one_line_naming_it(virtual, words):
    take = _take(A=np.zeros((2, 3)), B=np.ones((2, 3)))
    with pytest.raises(MocapError) as e:
        with_virtual_markers(take, _mapping(virtual))
    msg = str(e.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, msg


def test_an_empty_virtual_marker_is_a_mapping_error(tmp_path):
    p = tmp_path / "m.toml"
    p.write_text('[limbs.hat]\nmarkers = ["A", "B"]\n[virtual_markers]\nMID = []\n')
    with pytest.raises(MocapError) as e:
        load_mapping(p)
    assert "virtual_markers" in str(e.value) and "\n" not in str(e.value)
