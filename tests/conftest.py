import numpy as np
import pytest

import popup


@pytest.fixture(scope="session")
def model() -> popup.Model:
    return popup.Model()


@pytest.fixture(scope="session")
def encoder_run():
    """A smooth 2 s encoder trajectory at 500 Hz: shoulder and elbow moves."""
    t = np.arange(0, 2.0 + 1e-12, 0.002)
    s = 0.5 - 0.5 * np.cos(np.pi * np.clip(t / 1.5, 0, 1))
    q = np.stack([0.2 * s, 0.6 * s, -0.3 * s], axis=1)
    return t, q
