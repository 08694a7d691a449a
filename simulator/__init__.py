"""v2e-style DVS event simulator (no bpy): event type, pixel model, files."""
from simulator.config import SimulatorConfig
from simulator.events import EVENT_DTYPE, EventStream, EventValidationError, empty_events, make_events, to_torch, validate_events
from simulator.simulator import EventSimulator, FrameError, simulate

__all__ = ["EVENT_DTYPE", "EventStream", "EventValidationError", "EventSimulator", "FrameError",
           "SimulatorConfig", "empty_events", "make_events", "simulate", "to_torch", "validate_events"]
