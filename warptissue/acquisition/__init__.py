"""Indentation-rig acquisition: the line protocol, the serial driver, a simulated rig and
the recorder.

The protocol is specified in ``docs/rig-protocol.md`` (and implemented in
:mod:`warptissue.acquisition.protocol`); :class:`RigClient` speaks it over any pyserial URL;
:class:`SimulatedRig` with :class:`RigServer` answers it over a pty or a loopback socket;
:class:`Recorder` runs a test and writes the experiment CSV and its JSON sidecar, applying a
:class:`ForceCalibration` when given one. Submodules beside them: ``conditioning`` (prepare a
record for fitting), ``rig_dynamics`` (the rig's own frequency response, Kim et al.) and
``calibration`` (force-sensor correction, Tong et al.).
"""

from warptissue.acquisition.calibration import ForceCalibration
from warptissue.acquisition.driver import CommandRefused, LinkCounters, LinkLost, RigClient
from warptissue.acquisition.protocol import ProtocolError, parse_line, parse_quantity
from warptissue.acquisition.recorder import (
    RampHold,
    Recorder,
    RecordingResult,
    Sine,
)
from warptissue.acquisition.simulator import (
    FaultPlan,
    ForceCurveTissue,
    PhysiologicalDisturbance,
    RigConfig,
    RigCounters,
    RigServer,
    SimulatedRig,
)

__all__ = [
    "CommandRefused",
    "FaultPlan",
    "ForceCalibration",
    "ForceCurveTissue",
    "LinkCounters",
    "LinkLost",
    "PhysiologicalDisturbance",
    "ProtocolError",
    "RampHold",
    "RecordingResult",
    "Recorder",
    "RigClient",
    "RigConfig",
    "RigCounters",
    "RigServer",
    "SimulatedRig",
    "Sine",
    "parse_line",
    "parse_quantity",
]
