import numpy as np
import pytest

from simulator import SimulatorConfig

EPS = SimulatorConfig().log_eps


def frame_from_log(L) -> np.ndarray:
    """Linear float64 frame whose log(I + eps) equals L (up to float rounding)."""
    return np.exp(np.asarray(L, dtype=np.float64)) - EPS


@pytest.fixture
def rng():
    return np.random.default_rng(1234)
