"""The classical estimator returns flags, never exceptions, on any finite trace."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from stickslip.estimators.classical import estimate_array
from stickslip.estimators.classical import estimator as E

finite = st.floats(-50, 50, allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=60, deadline=None)
@given(force=arrays(np.float64, st.integers(16, 400), elements=finite))
def test_random_traces(force):
    x = np.arange(force.size) * 0.02
    out = estimate_array(x, force[None, :], 0.246, 296.0, 30.0)
    assert out.shape == (1, E.N_FIELDS)


def test_degenerate_traces():
    x = np.arange(512) * 11 / 512
    cases = [
        np.zeros(512),  # flat
        np.full(512, 3.0),
        np.round(np.sin(x * 40) * 2) / 2,  # coarse digitisation: exact +-1 levels
        np.where(np.arange(512) % 12 == 0, -1.0, 1.0),  # spikes
        (x % 0.246) / 0.246,  # ideal sawtooth reaching exactly F_max
        -((x % 0.246) / 0.246),  # sawtooth running backwards
    ]
    out = estimate_array(x, np.stack(cases), 0.246, 296.0, 30.0)
    assert out.shape == (len(cases), E.N_FIELDS)
