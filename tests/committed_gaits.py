"""The gaits the tests share, committed as data, and the exact recipes that regenerate them.

Tests load these files instead of optimizing a gait at test time, so what they check does not
depend on which local optimum IPOPT reaches on a given machine; ``tests/test_committed_gaits.py``
regenerates each one and checks that it still walks and still equals the committed file.

Regenerate one (after a change of the model, the optimizer or a default), from the repository
root::

    python -m tests.committed_gaits NAME        # writes the committed file in place
    python -m tests.committed_gaits NAME --out G.json

NAME is one of :data:`RECIPES`; "reference" first, since the default synthetic subject (and so
"demo") walks it.  The NOTICE beside each file repeats its recipe.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from characterization.gait.fit import fit_gait, verify_gait, walking_failures
from characterization.gait.phzd import PHZDOptions, optimize_gait
from hp_model.domains import PAPER_DOMAINS
from hp_model.gait_artifact import Gait, save_gait
from hp_model.human_prosthesis import HumanProsthesisModel

ROOT = Path(__file__).resolve().parent.parent

#: the largest difference of any gait coefficient (Bezier coefficients in rad, v_hip in m/s,
#: phase bounds in m) between a regenerated gait and the committed one.  The optimization is
#: deterministic (single-threaded linear algebra, :mod:`hp_model.blas_threads`), so on one
#: machine kind the regenerated gait is the same bit for bit; the tolerance leaves room for
#: the last digits of another libm or BLAS kernel, far below anything a test measures.
COEFFICIENT_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Recipe:
    """How a committed gait is made: ``make(model, workdir)`` returns the verified gait."""

    name: str
    path: Path  # the committed file, relative to the repository root
    what: str
    make: Callable[[HumanProsthesisModel, Path], Gait]


def _fit_take(model: HumanProsthesisModel, work: Path, synth: dict, opt: PHZDOptions,
              segments: str = "touchdown") -> Gait:
    """mocap synth -> mocap process -> gait fit, as the CLI verbs do; ``segments="paper"``
    regresses the steps of the paper's rule (``[segmentation] method = "paper"``)."""
    from characterization.mocap.files import process_file
    from characterization.mocap.mapping import default_mapping
    from characterization.mocap.steps_artifact import load_steps
    from characterization.mocap.synthetic_subject import SynthOptions, synthesize, write_synthetic

    opts = SynthOptions(**synth)
    write_synthetic(work / "take", synthesize(model, opts), opts)
    process_file(work / "take" / "take.csv", work / "steps.npz", with_figures=False,
                 mapping=default_mapping("paper" if segments == "paper" else "contact"))
    return fit_gait(model, load_steps(work / "steps.npz"), opt, src=str(work / "steps.npz"),
                    segments=segments)


def make_template(model: HumanProsthesisModel, _work: Path) -> Gait:
    """The quick template gait (ps about 0.3 s): the default optimization of
    :func:`tests.gait_template.template_targets`."""
    from characterization.gait.design import build_gait
    from characterization.gait.phzd import GaitVerificationError
    from tests.gait_template import template_targets

    opt = PHZDOptions()
    targets = template_targets()
    res = optimize_gait(model, targets, opt)
    if not res.success:
        raise RuntimeError(f"template gait: IPOPT status {res.status}")
    gait = build_gait(model, res, targets, opt)
    v = verify_gait(model, gait)
    failed = walking_failures(v)
    if failed:
        raise GaitVerificationError(f"template gait does not walk: {'; '.join(failed)}")
    return gait.with_verification({**v, "walks": True})


def make_demo(model: HumanProsthesisModel, work: Path) -> Gait:
    """``hpcosim demo``'s gait: the default (model-generated) synthetic subject, seed 1,
    20 strides; default gait fit."""
    return _fit_take(model, work, {"n_strides": 20, "seed": 1}, PHZDOptions())


def make_reference(model: HumanProsthesisModel, work: Path) -> Gait:
    """The packaged reference gait that the default synthetic subject walks: the kinematic
    template subject, seed 1, 37 strides; gait fit with the touchdown slip bounded."""
    return _fit_take(model, work, {"source": "template", "seed": 1},
                     PHZDOptions(touchdown_slip=0.5))


def make_playback(model: HumanProsthesisModel, work: Path) -> Gait:
    """The playback tests' gait (ps about 0.8 s at a nearly constant hip velocity): the
    kinematic template subject, seed 1; the paper's segmentation and cost, a least
    touchdown velocity of 0.2 m/s, IPOPT's adaptive barrier."""
    return _fit_take(model, work, {"source": "template", "seed": 1},
                     PHZDOptions(touchdown_velocity=0.2, w_offset=0.0, mu_strategy="adaptive"),
                     segments="paper")


RECIPES: dict[str, Recipe] = {r.name: r for r in (
    Recipe("reference", Path("characterization/data/reference_gait.json"),
           "packaged reference gait of the default synthetic subject", make_reference),
    Recipe("template", Path("tests/data/gaits/template.json"),
           "quick template gait of the controller, FMU and co-simulation tests", make_template),
    Recipe("demo", Path("tests/data/controller/gait_demo.json"),
           "the demo subject's gait", make_demo),
    Recipe("playback", Path("tests/data/playback/gait_synthetic.json"),
           "nominal gait of the playback tests' model-generated subject", make_playback),
)}


def regenerate(name: str, model: HumanProsthesisModel) -> Gait:
    """Make the committed gait ``name`` anew (in a scratch folder)."""
    with tempfile.TemporaryDirectory() as tmp:
        return RECIPES[name].make(model, Path(tmp))


def coefficient_difference(a: Gait, b: Gait) -> float:
    """Largest absolute difference of the gaits' packed parameters over both domains."""
    return float(max(np.abs(a.theta(d) - b.theta(d)).max() for d in PAPER_DOMAINS))


def assert_walks(model: HumanProsthesisModel, gait: Gait, name: str, steps: int = 20) -> None:
    """What a test that needs a walking gait checks first: ``steps`` steps of the full model
    under the gait's own feedback linearization, from its optimized start."""
    from characterization.gait.verification import make_simulator, simulate_gait

    run = simulate_gait(make_simulator(model, gait), gait, steps)
    assert not run.failed and run.steps >= steps, (
        f"the committed {name} gait does not walk on this model: {run.steps} of {steps} steps"
        f" ({run.reason}); regenerate it: python -m tests.committed_gaits {name}")


def load_committed(model: HumanProsthesisModel, name: str) -> Gait:
    """The committed gait ``name``, loaded for ``model`` and checked to walk."""
    from hp_model.gait_artifact import load_gait

    gait = load_gait(ROOT / RECIPES[name].path, model.parameter_hash())
    assert_walks(model, gait, name)
    return gait


def main(argv: list[str] | None = None) -> int:
    import hp_model

    ap = argparse.ArgumentParser(prog="python -m tests.committed_gaits", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("name", choices=sorted(RECIPES))
    ap.add_argument("--out", type=Path, help="where to write (default: the committed file)")
    args = ap.parse_args(argv)
    recipe = RECIPES[args.name]
    gait = regenerate(args.name, hp_model.load_model())
    out = args.out or ROOT / recipe.path
    out.parent.mkdir(parents=True, exist_ok=True)
    save_gait(out, gait)
    v = gait.verification
    print(f"{out}: gait {gait.hash()}, {v['steps_simulated']} steps, return-map spectral "
          f"radius {v['spectral_radius']:.3g}, IPOPT {gait.solver['iterations']} iterations")
    return 0


if __name__ == "__main__":
    sys.exit(main())
