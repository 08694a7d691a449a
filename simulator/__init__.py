"""v2e-style DVS event simulator (no bpy): event type, pixel model, files."""
import common  # noqa: F401  (first: it sets the OpenMP wait policy before torch or numba loads)
from simulator.config import SimulatorConfig
from simulator.events import EVENT_DTYPE, EventStream, EventValidationError, empty_events, make_events, to_torch, validate_events
from simulator.simulator import EventSimulator, FrameError, simulate

__all__ = ["EVENT_DTYPE", "EventStream", "EventValidationError", "EventSimulator", "FrameError",
           "SimulatorConfig", "empty_events", "make_events", "simulate", "to_torch", "validate_events"]
