"""The gaits the tests share are committed data (tests/committed_gaits.py); here each recipe
is run again and its result must still walk and still be the committed gait.

"demo" is regenerated through the command line by tests/test_gait_cli.py.  A failure here
means the model, the optimizer or a default changed what the recipe makes: regenerate the
file (``python -m tests.committed_gaits NAME``), rerun the suite, and commit both.
"""

from __future__ import annotations

import pytest

from hp_model.gait_artifact import load_gait
from tests.committed_gaits import (
    COEFFICIENT_TOLERANCE,
    RECIPES,
    ROOT,
    assert_walks,
    coefficient_difference,
)

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("name", ["reference", "template", "playback"])
def test_recipe_makes_the_committed_gait(name, model, regenerated):
    made = regenerated(name)
    v = made.verification
    assert v["walks"] and v["steps_simulated"] >= 20, v
    assert v["spectral_radius"] < 1.0, v["spectral_radius"]
    assert_walks(model, made, name)
    committed = load_gait(ROOT / RECIPES[name].path, model.parameter_hash())
    diff = coefficient_difference(made, committed)
    assert diff <= COEFFICIENT_TOLERANCE, (
        f"{name}: the recipe now makes a gait {diff:.3g} from the committed one "
        f"(python -m tests.committed_gaits {name} regenerates it)")
