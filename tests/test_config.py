"""Subject and device configs: the shipped files load; bad files fail with one line naming
the file and the field."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import hp_model
from hp_model import anthropometry as anth
from hp_model.config import ConfigError, load_device, load_subject


def _edit(tmp_path: Path, src: Path, old: str, new: str, name: str = "cfg.toml") -> Path:
    text = src.read_text()
    assert old in text, f"fixture text {old!r} not in {src.name}"
    p = tmp_path / name
    p.write_text(text.replace(old, new, 1))
    return p


def test_shipped_configs_load():
    s = load_subject(hp_model.default_subject_path())
    d = load_device(hp_model.default_device_path())
    assert s.body_mass > 0 and d.prosthesis.knee.gear_ratio.value > 0
    # every device value carries its provenance
    for link in (d.prosthesis.top, d.prosthesis.shin):
        assert link.mass.estimate and link.mass.source


@pytest.mark.parametrize(
    ("old", "new", "field", "why"),
    [
        ("body_mass = 60.0", "body_mass = -60.0", "body_mass", "greater than 0"),
        ("thigh = 0.404", "", "lengths.thigh", "Field required"),
        ("sex = \"female\"", "sex = \"female\"\nheight = 1.65", "height", "Extra inputs"),
        ("sex = \"female\"", "sex = \"other\"", "sex", "male"),
        ("schema_version = 1", "schema_version = 7", "schema_version", "not supported"),
    ],
)
def test_bad_subject_is_one_line_naming_file_and_field(tmp_path, old, new, field, why):
    p = _edit(tmp_path, hp_model.default_subject_path(), old, new, "subject.toml")
    with pytest.raises(ConfigError) as e:
        load_subject(p)
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(str(p)) and f"field '{field}'" in msg and why in msg


def test_bad_device_negative_mass(tmp_path):
    p = _edit(tmp_path, hp_model.default_device_path(),
              "mass    = { value = 2.2,", "mass    = { value = -2.2,", "device.toml")
    with pytest.raises(ConfigError, match=r"field 'prosthesis\.shin\.mass\.value'"):
        load_device(p)


def test_device_value_without_provenance_is_refused(tmp_path):
    src = hp_model.default_device_path()
    text = re.sub(r'(gear_ratio   = \{ value = 50\.0), estimate = true, source = "[^"]*"',
                  r"\1", src.read_text(), count=1)
    p = tmp_path / "device.toml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=r"prosthesis\.knee\.gear_ratio\.estimate"):
        load_device(p)


def test_unreadable_and_malformed_files(tmp_path):
    with pytest.raises(ConfigError, match="cannot read"):
        load_subject(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("name = \n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_subject(bad)


def test_segment_table_worked_example():
    """REFERENCE.md: 75 kg male, 0.42 m thigh, Winter radii: m = 7.875 kg, I = 0.145."""
    m, c, inertia = anth.segment("thigh", "male", "winter", 75.0, 0.42)
    assert m == pytest.approx(7.875)
    assert c == pytest.approx(0.433 * 0.42)
    assert inertia == pytest.approx(0.145, abs=5e-4)


def test_model_mass_is_subject_plus_device():
    model = hp_model.load_model()
    s, d = model.subject, model.device
    sex = s.sex
    fractions = 2 * sum(anth.MASS_FRACTION[k][sex] for k in ("thigh", "shank", "foot"))
    human = s.body_mass * (fractions + anth.MASS_FRACTION["hat"][sex])
    device = d.iwalk.mass.value + sum(
        x.mass.value for x in (d.prosthesis.top, d.prosthesis.shin, d.prosthesis.foot))
    assert model.tree.total_mass == pytest.approx(human + device, rel=1e-12)
