"""warptissue.fit.live (the inverse FE as a live fit) through ``warptissue acquire --fit
STUDY.toml``, against a simulated rig whose specimen is a known neo-Hookean's FE force
(warptissue.simulate.force_curve_tissue, ``rig-sim --tissue study:FILE``)."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from warptissue.acquisition import RigConfig, RigServer, SimulatedRig
from warptissue.cli import main
from warptissue.errors import InputError
from warptissue.fit.live import StudyFitter
from warptissue.io import read_experiment_csv
from warptissue.simulate import force_curve_tissue
from warptissue.study import load_study, study_from_dict

TRUE_C10_PA = 400.0
"""C10 of the simulated rig's specimen (the fit study starts from 287.5 Pa)."""

ROOT = Path(__file__).resolve().parents[1]
SPECIMEN = ROOT / "scenes" / "live_punch_specimen.toml"
"""The known neo-Hookean specimen (C10 = TRUE_C10_PA) served by the simulated rig."""
FIT_STUDY = (ROOT / "scenes" / "live_punch_fit.toml").read_text(encoding="utf-8")
"""The live fit study (the docs' example), its [[data]] file a placeholder."""
PLACEHOLDER = 'file = "replaced-by-the-record.csv"'


def fit_study(record: Path | str) -> str:
    """The live fit study with ``record`` as its [[data]] file."""
    assert PLACEHOLDER in FIT_STUDY
    return FIT_STUDY.replace(PLACEHOLDER, f"file = {json.dumps(str(record))}")


def specimen_tissue():
    """The known neo-Hookean's FE force-depth curve to 0.3 mm (6 steps)."""
    assert tomllib.loads(SPECIMEN.read_text(encoding="utf-8"))["material"]["C10_Pa"] == TRUE_C10_PA
    return force_curve_tissue(load_study(SPECIMEN))


def test_the_study_tissue_is_the_fe_force_curve():
    """An independent check of the force scale: at small depth a flat punch on a layer
    is Sneddon's half-space force 4 G a d / (1 - nu) stiffened by the layer (Hayes et al.'s
    factor, about 1.5 for a / h = 0.25), so the FE force at 0.05 mm lies between Sneddon's
    and twice it."""
    tissue = specimen_tissue()
    depth = np.array([0.0, 5e-5, 3e-4, 4e-4])
    force = tissue.force_N(np.zeros(4), depth)
    shear_Pa, nu = 2 * TRUE_C10_PA, 0.5 - 3 * 2 * TRUE_C10_PA / (2 * 3 * 575000.0)
    sneddon_N = 4 * shear_Pa * 1e-3 * 5e-5 / (1 - nu)
    assert force[0] == 0.0 and sneddon_N < force[1] < 2 * sneddon_N
    assert force[3] == force[2]  # held at the deepest step beyond it


def test_a_viscoelastic_study_tissue_is_refused():
    table = tomllib.loads(SPECIMEN.read_text(encoding="utf-8"))
    table.update(
        schema_version=2,
        name="visco",
        material={
            "model": "neo_hookean",
            "C10_Pa": 400.0,
            "bulk_modulus_Pa": 575000.0,
            "g1": 0.3,
            "tau1_s": 1.0,
        },
    )
    table["protocol"] = {
        "kind": "ramp_hold",
        "max_depth_m": 3e-4,
        "speed_m_per_s": 1e-3,
        "hold_s": 1.0,
    }
    with pytest.raises(InputError, match="elastic material"):
        force_curve_tissue(study_from_dict(table))


def test_a_live_study_takes_one_data_table(tmp_path):
    path = tmp_path / "two.toml"
    path.write_text(fit_study("live.csv") + '\n[[data]]\nfile = "other.csv"\n', encoding="utf-8")
    with pytest.raises(InputError, match=r"one \[\[data\]\] table"):
        StudyFitter.from_file(path, record_path=tmp_path / "live.csv")
    path.write_text(FIT_STUDY.split("[fit]")[0], encoding="utf-8")
    with pytest.raises(InputError, match=r"\[fit\] table"):
        StudyFitter.from_file(path, record_path=tmp_path / "live.csv")


@pytest.mark.slow
def test_live_study_fit_ends_with_the_offline_fit_of_the_saved_record(tmp_path, capsys):
    """acquire --fit STUDY.toml --usd against the known neo-Hookean (surface 0.1 mm below the
    start, its position given to the conditioning, 0.3 mm indented, real time): the live fit
    refits at the end of the ramp and of the hold; the final C10 is that of 'warptissue fit
    indentation' of a study naming the saved CSV (to 1e-6 relative), so is the last live
    estimate's (warm-started on the whole record), and both recover the specimen's C10."""
    config = RigConfig(
        time_scale=1.0,
        surface_position_m=1e-4,
        force_resolution_N=1e-7,  # the default 0.7 mN is a third of the largest force
        force_noise_N=2e-6,
        seed=3,
    )
    rig = SimulatedRig(specimen_tissue(), config)
    study = tmp_path / "study.toml"
    study.write_text(FIT_STUDY, encoding="utf-8")
    out = tmp_path / "run.csv"
    with RigServer(rig, transport="tcp") as server:
        status = main(["acquire", "--port", server.url, "--depth", "0.4mm", "--speed",
                       "0.1mm/s", "--hold", "1s", "--rate", "50Hz", "--out", str(out),
                       "--no-progress", "--fit", str(study), "--usd"])  # fmt: skip
    printed = capsys.readouterr().out
    assert status == 0, printed
    folder = tmp_path / "run_indentation_fit"
    live = json.loads((folder / "run_live.json").read_text())
    assert live["state"] == "finished" and live["recording_status"] == "complete"
    estimates = [e for e in live["estimates"] if "parameters" in e]
    assert len(estimates) >= 2  # the end of the ramp and the end of the record
    assert estimates[-1]["samples"] == read_experiment_csv(out).sample_count
    final = json.loads((folder / "fit.json").read_text())["parameters"]["C10_Pa"]["value"]
    offline_study = tmp_path / "offline.toml"
    offline_study.write_text(fit_study(out), encoding="utf-8")
    offline_dir = tmp_path / "offline"
    assert main(["fit", "indentation", str(offline_study), "--out", str(offline_dir),
                 "--quiet"]) == 0  # fmt: skip
    offline = json.loads((offline_dir / "fit.json").read_text())["parameters"]["C10_Pa"]
    assert final == pytest.approx(offline["value"], rel=1e-6)
    last_live = estimates[-1]["parameters"]["C10_Pa"]["value"]
    assert last_live == pytest.approx(offline["value"], rel=1e-6)
    assert final == pytest.approx(TRUE_C10_PA, rel=0.02)
    assert (folder / "specimen.usda").stat().st_size > 0
    assert (folder / "run_live.png").stat().st_size > 0
    assert Path(folder / "run_study.toml").exists()
