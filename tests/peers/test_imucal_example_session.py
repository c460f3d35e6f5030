"""imucal's own example Ferraris session (measured, MIT, data/real/imucal_ferraris): imported as a lab user would,
its three guided turns used, and the product judged beside imucal on the face-to-face turns that neither fits."""

import gzip
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from graph_calib import io
from graph_calib.calibrate import calibrate
from graph_calib.cli import main
from graph_calib.compensation.calibration import Calibration
from graph_calib.evaluation.crossval import face_to_face_folds, held_out_figures, record_rests, training_record
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions
from graph_calib.solvers.verdict import kind_limits

from imucal_peer import imucal_ferraris

pytestmark = pytest.mark.slow

SESSION = Path(__file__).resolve().parents[2] / "data" / "real" / "imucal_ferraris" / "example_ferraris_session.csv.gz"


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    folder = tmp_path_factory.mktemp("imucal_session")
    csv = folder / "example_ferraris_session.csv"
    with gzip.open(SESSION, "rb") as src, open(csv, "wb") as dst:
        shutil.copyfileobj(src, dst)
    out = folder / "ferraris.h5"
    assert main(["import", "csv", str(csv), "--rate-hz", "102.4", "--gyro-units", "deg/s", "--temperature", "20",
                 "--latitude-deg", "49.6", "--out", str(out)]) == 0
    return out


def test_the_counter_is_the_time_and_the_three_guided_turns_are_used(session, tmp_path):
    exp = io.read_experiment(session)
    assert exp.n_samples == 10376 and exp.rate_hz == 102.4
    main(["calibrate", str(session), "--out", str(tmp_path / "c"), "--solver", "factor-graph"])
    result = json.loads((tmp_path / "c" / "factor-graph.json").read_text())
    assert result["noise"]["guided_turns"]["count"] == 3
    turn = result["residuals"]["kinds"]["turn"]
    lo, hi = kind_limits(turn["redundancy"])
    # imucal's guide kept to half a degree: the turns' residuals fit the declared spread (1.06 measured)
    assert lo < turn["chi2_per_redundancy"] < hi
    assert any("taken as a Ferraris session's guided turns" in n for n in result["verdict"]["notes"])


def _face_folds(exp, rests, guided):
    options = CalibrationOptions(model=ModelOptions(grade="consumer", guided_turns=guided))
    out = []
    for fold in face_to_face_folds(exp, folds=2, rests=rests):
        r = calibrate(training_record(exp, fold, rests=rests), options=options,
                      solvers=("factor-graph",)).results["factor-graph"]
        out.append(held_out_figures(exp, fold, Calibration.from_result(r)).transitions_rms_deg)
    return np.array(out)


def test_the_guided_turns_halve_the_held_out_face_to_face_error(session):
    """Held out: the face-to-face turns of each fold (every rest and full turn stays in training). Measured: the turns
    taken for motion 2.80 and 1.82 deg, guided 1.31 and 0.82 deg; imucal (fitted on the faces and the full turns,
    never on these) 0.78 and 0.76 deg: its protocol's box axes give it the misalignments the product estimates."""
    exp = io.read_experiment(session)
    rests = record_rests(exp)
    off, guided = _face_folds(exp, rests, False), _face_folds(exp, rests, True)
    peer = imucal_ferraris(exp, rests)
    theirs = np.array([held_out_figures(exp, fold, peer).transitions_rms_deg
                       for fold in face_to_face_folds(exp, folds=2, rests=rests)])
    assert np.sqrt(np.mean(guided**2)) < 0.55 * np.sqrt(np.mean(off**2))
    assert np.all(guided < off)
    assert np.sqrt(np.mean(guided**2)) < 1.6 * np.sqrt(np.mean(theirs**2))


def test_diagnose_adopts_nothing_that_holds_out_worse_and_says_what_is_left(session, tmp_path):
    """The loop's candidates (gyro.scale_asym first) fit the record better and hold it out worse: none is adopted, and
    the verdict still names what the residuals carry (exit 3)."""
    assert main(["diagnose", str(session), "--out", str(tmp_path / "d"), "--solver", "factor-graph"]) == 3
    doc = json.loads((tmp_path / "d" / "diagnosis.json").read_text())
    assert doc["added"] == []
    assert "turn" in doc["before"]["residuals"]["factor-graph"]
    assert "RESIDUALS CARRY AN EFFECT THE MODEL LACKS" in doc["verdict"]["text"]
