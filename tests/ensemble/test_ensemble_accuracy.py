"""A study says how accurate its members are: each member's error estimate and goal are in the dataset, and members
beyond their goal are named in the summary and by an AccuracyWarning, never silent."""
import warnings

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.accuracy import AccuracyWarning
from linknet_core.ensemble import summary

from .ensemble_support import MODELS


def test_members_beyond_their_goal_are_said_and_the_default_is_within():
    with pytest.warns(AccuracyWarning, match="2 of 2 members' estimated position error exceeds their goal"):
        coarse = ln.ensemble(MODELS / "chain_10.json", vary={"M[3]": [0.5, 2.0]}, t_end=0.5, n_out=6, workers=1,
                             method="rattle", dt=1e-3)
    assert np.all(coarse["error_estimate"].values > coarse["error_goal"].values)
    assert "WARNING: 2 of 2 members" in summary(coarse)
    # each member's estimate is its serial run's (the same companion rule)
    serial = ln.simulate(ln.load_scene(MODELS / "chain_10.json").with_parameters(
        mass=np.where(np.arange(11) == 2, 0.5, ln.load_scene(MODELS / "chain_10.json").mass)),
        0.5, method="rattle", dt=1e-3, n_out=6)
    assert coarse["error_estimate"].values[0] == pytest.approx(serial.max_error_estimate, rel=1e-6)
    with warnings.catch_warnings():
        warnings.simplefilter("error", AccuracyWarning)
        fine = ln.ensemble(MODELS / "chain_10.json", vary={"M[3]": [0.5, 2.0]}, t_end=0.5, n_out=6, workers=1)
    assert np.all(fine["error_estimate"].values <= fine["error_goal"].values)
    assert "every member within its goal" in summary(fine)
