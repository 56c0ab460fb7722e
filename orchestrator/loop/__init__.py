"""The one closed loop of plant, link and recorder (:func:`run_loop`), the plants (the
in-process simulator, the human FMU) and the in-process links; see ``run.py``."""

from orchestrator.loop.link import (
    IDEAL_ENCODER,
    Command,
    ControllerLink,
    Encoder,
    Link,
    OracleLink,
    measurement,
)
from orchestrator.loop.plant import (
    FmuEndError,
    FmuPlant,
    Observation,
    Plant,
    Sensed,
    SimulatorPlant,
    Truth,
    observe_state,
)
from orchestrator.loop.run import LoopLog, Recorder, run_loop

__all__ = ["IDEAL_ENCODER", "Command", "ControllerLink", "Encoder", "FmuEndError", "FmuPlant",
           "Link",
           "LoopLog", "Observation", "OracleLink", "Plant", "Recorder", "Sensed",
           "SimulatorPlant", "Truth", "measurement", "observe_state", "run_loop"]
