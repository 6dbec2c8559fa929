"""Study files: the TOML record of one indentation simulation.

A study names the specimen and its mesh, the indenter, the loading protocol, the material,
the boundary conditions and the solver settings. It is the reproducible record of a run and
the unit of batch work: ``warptissue simulate STUDY.toml`` runs one, and the result JSON
echoes it back with every default filled in.

The schema is versioned. Version 1 describes a simulation; version 2 (:data:`SCHEMA_VERSION`)
adds the tables of a fit: ``[[data]]``, the measured records (CSV files relative to the study
file, their columns and their conditioning, read and conditioned on loading), and ``[fit]``,
which material parameters are free, their bounds and start values, the least-squares method
and its tolerances. Version-1 files load unchanged. Every key carries its unit in its name
(``thickness_m``, ``C10_Pa``). Loading validates the whole file: an unknown key, a missing
key, a value of the wrong type or out of range raises :class:`~warptissue.errors.InputError`
naming the file, the line, the key path (for example ``material.C10_Pa`` or
``data[0].keep_depth_m``) and the value, with the closest known name where one is close.

:func:`warptissue.fit.start.start_values_from_record` gives the start of every free parameter
from the small-depth stiffness of a record (Sneddon's flat punch with the Hayes layer factor);
:func:`save_study` writes a study (a fitted one, say) back as TOML, its data paths relative to
the new file.

Example:
    >>> from warptissue.study import load_study
    >>> study = load_study("scenes/liver_slab_flat_punch.toml")  # doctest: +SKIP
    >>> study.protocol.depths_m[-1]  # doctest: +SKIP
    0.0005
"""

from warptissue._deprecated import moved_names
from warptissue.study._collect import collect_studies, folder_names
from warptissue.study._organ import (
    MESH_UNITS,
    organ_mesh,
    probe_placement,
    specimen_mesh,
    support_nodes,
)
from warptissue.study._reader import load_study, study_from_dict
from warptissue.study._schema import (
    BULK_MODULUS_RULES,
    CONTACT_POINTS,
    DEPTH_OFFSET,
    DEVICE_PATTERN,
    FIT_METHODS,
    FIT_OBJECTIVES,
    FIT_STRATEGIES,
    PROTOCOL_KINDS,
    SCHEMA_VERSION,
    SCHEMA_VERSIONS,
    START_FROM,
    Boundary,
    DataRecord,
    FitSettings,
    Protocol,
    Solver,
    Specimen,
    Study,
)
from warptissue.study._sizing import CONTACT_RADIUS_SAFETY, mesh_probe_radius
from warptissue.study._writer import save_study

__all__ = [
    "FIT_METHODS",
    "FIT_OBJECTIVES",
    "CONTACT_POINTS",
    "CONTACT_RADIUS_SAFETY",
    "DEPTH_OFFSET",
    "DEVICE_PATTERN",
    "FIT_STRATEGIES",
    "BULK_MODULUS_RULES",
    "PROTOCOL_KINDS",
    "SCHEMA_VERSION",
    "SCHEMA_VERSIONS",
    "START_FROM",
    "Boundary",
    "DataRecord",
    "FitSettings",
    "Protocol",
    "Solver",
    "Specimen",
    "Study",
    "MESH_UNITS",
    "collect_studies",
    "folder_names",
    "load_study",
    "mesh_probe_radius",
    "organ_mesh",
    "probe_placement",
    "specimen_mesh",
    "support_nodes",
    "save_study",
    "study_from_dict",
]

# The old paths of names that moved, with a DeprecationWarning naming the new one
# (warptissue._deprecated.MOVED).
__getattr__ = moved_names(__name__)
