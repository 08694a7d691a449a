"""v2e-style DVS event simulator (no bpy): the pixel model and its kernels, frames to event files.
The event stream type and the file formats are `eventio`'s (re-exported here for the simulator's API)."""
import common  # noqa: F401  (first: it sets the OpenMP wait policy before torch or numba loads)
from eventio.events import EVENT_DTYPE, EventStream, EventValidationError, empty_events, make_events, to_torch, validate_events
from simulator.config import SimulatorConfig
from simulator.simulator import EventSimulator, FrameError, simulate

__all__ = ["EVENT_DTYPE", "EventStream", "EventValidationError", "EventSimulator", "FrameError",
           "SimulatorConfig", "empty_events", "make_events", "simulate", "to_torch", "validate_events"]
