"""Identification on actuators hystmpc has no family for (tests/heldout_truths.py): each is
recorded as a user would (20 s from rest, moves at several speeds, holds, a decaying sine) and
validated on a second, independent record. ``identify auto`` must beat a straight line through
a first-order lag by a wide margin; how far it stays from the sensor noise is reported (the
figures in docs/identification.md come from the same runs)."""

import numpy as np
import pytest
from heldout_truths import TRUTHS, record

from hystmpc.models.identify_auto import identify_auto

SETTINGS = {  # what a user would ask for, knowing the actuator's kind
    "preisach-creep": {"dynamics": "first-order", "creep": "kelvin-voigt"},
    "bouc-wen-resonance": {"dynamics": "second-order"},
    "rate-dependent-play": {"dynamics": "first-order"},
    "duhem-saturation": {"dynamics": "first-order"},
    "duhem-monotone": {"dynamics": "first-order"},
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(TRUTHS))
def test_identify_auto_on_a_held_out_truth(name):
    truth = TRUTHS[name]()
    u, y = record(truth, 20.0, 1)
    validation = record(truth, 10.0, 2)
    ranking = identify_auto(u, y, truth.sample_period, validation, **SETTINGS[name])
    best, naive = ranking.best, ranking.naive
    print(f"\n{name}: {best.family} validates at {best.validation_rmse / truth.noise:.2f} × the noise, "
          f"{best.validation_rmse / naive.validation_rmse:.3f} × the linear + lag model")
    assert np.isfinite(best.validation_rmse)
    assert best.validation_rmse <= 0.35 * naive.validation_rmse
