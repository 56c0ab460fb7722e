"""A committed multi-contact cycle for the closed-loop tests: openOFM's walk fitted by
``gait fit --domains multicontact`` (the take's subject, the pylon cut to its leg), stored
as the fit's per-domain trajectories and the model's configs (tests/data/gaits/NOTICE.md).

Regenerate, from the repository root (about a minute):

    python -m tests.multicontact_cycle
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from hp_model.config import DeviceConfig, SubjectConfig
from hp_model.domains import Domain, DomainGraph
from hp_model.human_prosthesis import HumanProsthesisModel

PATH = Path(__file__).parent / "data" / "gaits" / "openofm_multicontact_cycle.npz"
TAKE = Path(__file__).parent / "data" / "openofm-walk"
KEYS = ("t", "q", "qd", "qdd", "u", "lam")


def save_cycle(path: Path, model: HumanProsthesisModel, trajectory: dict, durations: dict,
               stride_length: float) -> None:
    arrays: dict[str, Any] = {f"{d.value}.{k}": np.asarray(trajectory[d][k], float)
              for d in model.graph.domains for k in KEYS}
    meta = {"subject": model.subject.model_dump(mode="json"),
            "device": model.device.model_dump(mode="json"),
            "durations": {d.value: float(durations[d]) for d in model.graph.domains},
            "stride_length": float(stride_length)}
    np.savez_compressed(path, meta=np.array(json.dumps(meta)), **arrays)


def load_cycle(path: Path = PATH) -> tuple[HumanProsthesisModel, dict[Domain, dict[str, Any]],
                                          dict[Domain, float], float]:
    """(model, trajectories, durations (s), stride length (m))."""
    with np.load(path) as z:
        meta = json.loads(str(z["meta"]))
        graph = DomainGraph.MULTICONTACT
        traj = {d: {k: z[f"{d.value}.{k}"] for k in KEYS} for d in graph.domains}
    model = HumanProsthesisModel(SubjectConfig.model_validate(meta["subject"]),
                                 DeviceConfig.model_validate(meta["device"]), graph=graph)
    durations = {Domain(d): float(v) for d, v in meta["durations"].items()}
    return model, traj, durations, float(meta["stride_length"])


def write_gait_file(path: Path, cycle_path: Path = PATH) -> HumanProsthesisModel:
    """The committed cycle as a multi-contact gait file (what ``gait fit --domains
    multicontact`` writes, the parts its readers use: the trajectories, the model's configs
    and hash); its model."""
    from characterization.gait.multicontact_artifact import KIND, SCHEMA_VERSION
    from hp_model.artifacts import save_json

    model, traj, durations, _ = load_cycle(cycle_path)
    save_json(path, {
        "kind": KIND, "schema_version": SCHEMA_VERSION, "model_hash": model.parameter_hash(),
        "domain_graph": model.graph.value, "domains": [d.value for d in model.graph.domains],
        "trajectory": {d.value: {"duration": durations[d], **traj[d]}
                       for d in model.graph.domains},
        "subject": model.subject.model_dump(mode="json"),
        "device": model.device.model_dump(mode="json")})
    return model


def main() -> int:
    from characterization.gait.fit import worn_device
    from characterization.gait.multicontact import (
        GRAPH,
        MultiContactOptions,
        fit_multicontact,
        targets_from_steps,
    )
    from characterization.mocap.steps_artifact import load_steps, steps_subject
    from hp_model.config import default_device_path, load_device
    from orchestrator.cli import main as hpcosim

    with tempfile.TemporaryDirectory() as tmp:
        steps_path = Path(tmp) / "steps.npz"
        if hpcosim(["mocap", "process", str(TAKE / "dynamic.c3d"), "--mapping",
                    str(TAKE / "mapping.toml"), "--out", str(steps_path), "--no-figures"]):
            return 1
        steps = load_steps(steps_path)
        found = steps_subject(steps, str(steps_path))
        assert found is not None, "mocap process stores the subject"
        subject = found[0]
        device, _ = worn_device(subject, load_device(default_device_path()))
        model = HumanProsthesisModel(subject, device, graph=GRAPH)
        result = fit_multicontact(model, targets_from_steps(steps, model), MultiContactOptions())
    if not result.success:
        print(f"the fit ended with {result.status}", file=sys.stderr)
        return 1
    save_cycle(PATH, model, result.trajectory, result.durations, result.stride_length)
    print(f"wrote {PATH}: stride {result.stride_time:.3f} s, {result.speed:.3f} m/s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
