"""An event file read with the sensor model that made it, typed: `EventFile(path).sensor` is the
SimulatorConfig stored with the events (range-checked). The file itself is `eventio.EventFile`;
this layer adds only what needs the simulator's config type.
"""
from __future__ import annotations

import dataclasses

from common.config import ConfigError, from_dict
from eventio.event_file import EventFile as _EventFile
from eventio.h5io import EventFileError
from simulator.config import SimulatorConfig


def sensor_of(events: _EventFile) -> SimulatorConfig:
    """The SimulatorConfig stored with an event file (fields it lacks take the defaults); a stored
    config that is not valid is an EventFileError naming the file."""
    names = {f.name for f in dataclasses.fields(SimulatorConfig)}
    try:
        return from_dict(SimulatorConfig, events.sensor_fields(names))
    except ConfigError as exc:
        raise EventFileError(f"{events.path}: the stored simulator config is not valid ({exc})") from None


class EventFile(_EventFile):
    """`eventio.EventFile` plus `.sensor`, the typed simulator config (read once)."""

    _sensor: SimulatorConfig | None = None

    @property
    def sensor(self) -> SimulatorConfig:
        if self._sensor is None:
            self._sensor = sensor_of(self)
        return self._sensor
