"""Indentation-rig acquisition: the line protocol, the serial driver, a simulated rig and
the recorder.

The protocol is specified in ``docs/rig-protocol.md`` (and implemented in
:mod:`warptissue.acquisition.protocol`); :class:`RigClient` speaks it over any pyserial URL;
:class:`SimulatedRig` with :class:`RigServer` answers it over a pty or a loopback socket;
:class:`Recorder` runs a test and writes the experiment CSV and its JSON sidecar.
"""

from warptissue.acquisition.driver import CommandRefused, LinkCounters, LinkLost, RigClient
from warptissue.acquisition.protocol import ProtocolError, parse_line, parse_quantity
from warptissue.acquisition.recorder import (
    PolynomialForceCalibration,
    RampHold,
    Recorder,
    RecordingResult,
    Sine,
    load_force_calibration,
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
    "ForceCurveTissue",
    "LinkCounters",
    "LinkLost",
    "PhysiologicalDisturbance",
    "PolynomialForceCalibration",
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
    "load_force_calibration",
    "parse_line",
    "parse_quantity",
]
