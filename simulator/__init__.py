"""v2e-style DVS event simulator (no bpy): the pixel model and its kernels, frames to event files.
The event stream type and the file formats are `eventio`'s (re-exported here for the simulator's API).

`EventSimulator`, `FrameError` and `simulate` load the simulator's numba kernels when first used, so
reading a sensor's config (`simulator.config`, which a scene's config holds) does not compile or
import them.
"""
import common  # noqa: F401  (first: it sets the OpenMP wait policy before torch or numba loads)
from eventio.events import EVENT_DTYPE, EventStream, EventValidationError, empty_events, make_events, to_torch, validate_events
from simulator.config import SimulatorConfig

_LAZY = {"EventSimulator", "FrameError", "simulate"}       # from simulator.simulator, loaded on first use

__all__ = ["EVENT_DTYPE", "EventStream", "EventValidationError", "EventSimulator", "FrameError",
           "SimulatorConfig", "empty_events", "make_events", "simulate", "to_torch", "validate_events"]


def __getattr__(name: str):
    if name in _LAZY:
        from simulator import simulator as _simulator

        return getattr(_simulator, name)
    raise AttributeError(f"module 'simulator' has no attribute {name!r}")
