"""An event file's sensor as the simulator's own typed config: `sensor_of(EventFile(path))` is the
SimulatorConfig stored with the events (range-checked), for code that needs every parameter typed.
What consumers need (thresholds, refractory period) is the file's plain record, `EventFile(path).sensor`
(eventio.sensor.SensorRecord).
"""
from __future__ import annotations

import dataclasses

from common.config import ConfigError, from_dict
from eventio.event_file import EventFile
from eventio.h5io import EventFileError
from simulator.config import SimulatorConfig


def sensor_of(events: EventFile) -> SimulatorConfig:
    """The SimulatorConfig stored with an event file (fields it lacks take the defaults); a stored
    config that is not valid is an EventFileError naming the file."""
    names = {f.name for f in dataclasses.fields(SimulatorConfig)}
    try:
        return from_dict(SimulatorConfig, events.sensor_fields(names))
    except ConfigError as exc:
        raise EventFileError(f"{events.path}: the stored simulator config is not valid ({exc})") from None
