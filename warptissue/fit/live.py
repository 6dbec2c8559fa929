"""The inverse FE as a live fit: a study's material refitted to the record as the rig records it.

:class:`StudyFitter` is a :class:`warptissue.acquisition.live.LiveFitter` for ``warptissue
acquire --fit STUDY.toml``. The study is a fit study (schema version 2) with **one**
``[[data]]`` table: the live record takes its place. Its ``file`` (and its column names) are
replaced by the record being acquired; everything else of the table is kept (``contact``,
``offset``, ``keep_depth_m``, ``window_s``: the conditioning of the growing record), and so is
the rest of the study (specimen, probe, material, ``[fit]``). Each refit writes the record so
far to ``record_path`` (atomically) and runs :func:`warptissue.fit.fit_indentation` on the
study with that record, its start values the last converged estimate (``[fit] start``; the
first refit starts as the study says).
"""

from __future__ import annotations

import copy
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.acquisition.live import LiveCurve
from warptissue.device import quiet_warp
from warptissue.errors import ConvergenceError, InputError
from warptissue.fit.indentation import fit_indentation
from warptissue.io import write_csv
from warptissue.lsq.result import FitResult
from warptissue.study import Study, study_from_dict

__all__ = ["StudyFitter"]

RECORD_COLUMNS = ("time_s", "displacement_m", "force_N")
"""The columns of the live record as the recorder writes them."""


@dataclass
class StudyFitter:
    """A study's inverse-FE fit of the record as it grows (see the module docstring).

    Build it with :meth:`from_file`.

    Attributes:
        study_path: The study file.
        table: The study as read from it (TOML mapping), its one ``[[data]]`` table the
            live record's.
        record_path: Where each refit writes the record so far (CSV, atomically).
        device: Warp device of the FE, or None (the study's ``solver.device``).
    """

    study_path: Path
    table: dict[str, Any]
    record_path: Path
    device: str | None = None
    _start: dict[str, float] | None = field(default=None, init=False, repr=False)

    @classmethod
    def from_file(
        cls, path: str | Path, *, record_path: str | Path, device: str | None = None
    ) -> StudyFitter:
        """Read a study file for a live fit.

        Args:
            path: The study (schema version 2, one ``[[data]]`` table, a ``[fit]`` table).
            record_path: Where the refits write the record so far.
            device: Warp device of the FE, or None.

        Raises:
            InputError: The file is missing or not TOML, or has no ``[fit]`` table or not
                exactly one ``[[data]]`` table (naming the file).
        """
        path = Path(path)
        try:
            table = tomllib.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise InputError(f"cannot read the study: {exc.strerror}", path=path) from None
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise InputError(f"not a valid TOML study: {exc}", path=path) from None
        if "fit" not in table:
            raise InputError("a live study fit needs a [fit] table", path=path, key="fit")
        data = table.get("data")
        if not isinstance(data, list) or len(data) != 1 or not isinstance(data[0], dict):
            raise InputError(
                "a live study fit takes one [[data]] table: the record being acquired takes "
                "its file's place",
                path=path,
                key="data",
            )
        return cls(path, table, Path(record_path), device)

    @property
    def label(self) -> str:
        """The study file's name."""
        return str(self.study_path)

    @property
    def free(self) -> list[str]:
        """The free parameters of ``[fit]``."""
        return list(self.table["fit"].get("free", []))

    def study_for(self, csv_path: str | Path, *, start: dict[str, float] | None = None) -> Study:
        """The study with its ``[[data]]`` record replaced by ``csv_path``.

        Args:
            csv_path: A record as ``warptissue acquire`` writes it.
            start: Start values of free parameters (replacing ``[fit] start``'s), or None.

        Raises:
            InputError: The study or the record is refused (as ``load_study``).
        """
        table = copy.deepcopy(self.table)
        data = table["data"][0]
        data["file"] = str(Path(csv_path).resolve())
        for column in RECORD_COLUMNS:
            data[column.split("_")[0] + "_column"] = column
        if start:
            table["fit"]["start"] = {**table["fit"].get("start", {}), **start}
        return study_from_dict(table, path=self.study_path)

    def refit(self, samples: np.ndarray, *, final: bool = False) -> tuple[FitResult, LiveCurve]:
        """Fit the study to the record so far, warm-started from the last converged fit.

        Args:
            samples: Shape (n, 3): time_s (s), displacement_m (m), force_N (N).
            final: The last refit, of the whole record (warm-started all the same: an FE
                fit from the study's own start costs as much as the final offline fit).

        Raises:
            InputError: The record so far is refused (no contact yet, too few samples).
            ConvergenceError: The FE fit did not converge.
        """
        quiet_warp()
        write_csv(self.record_path, dict(zip(RECORD_COLUMNS, samples.T, strict=True)))
        fit = fit_indentation(
            self.study_for(self.record_path, start=self._start),
            device=self.device,
            progress=False,
        )
        if not fit.success:
            raise ConvergenceError(f"the FE fit ended {fit.status}: {fit.message}")
        values = fit.parameters
        self._start = {name: float(values[name]) for name in self.free if name in values}
        curve = fit.records[0]
        return fit.result, LiveCurve(curve.time_s, curve.measured_force_N, curve.fitted_force_N)
