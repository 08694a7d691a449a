"""What an event file says about the sensor that made its events, as a plain record.

    rec = EventFile("events/cam0.h5").sensor      # SensorRecord(pos_threshold=0.2, neg_threshold=0.2, ...)
    rec.pos_threshold, rec.neg_threshold            # nominal ON / OFF contrast thresholds (log units)
    rec.log_mode, rec.log_eps, ...                  # the response the thresholds apply to
    rec.fields                                      # every stored parameter, by name

The simulator's config converts to one (`SimulatorConfig.sensor_record()`), and `simulator.event_file.
sensor_of` reads the whole typed config back where the simulator's own type is needed. A record is
range-checked when read: thresholds and the response's constants finite and > 0 (log_eps >= 0),
refractory period and threshold spread >= 0, log_mode log or linlog.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Mapping


NAMED = ("pos_threshold", "neg_threshold", "threshold_sigma", "refractory_us", "log_mode", "log_eps",
         "linlog_threshold_dn", "linlog_dn_per_unit")


@dataclass(frozen=True)
class SensorRecord:
    """The sensor parameters stored with an event file; a value the file does not hold takes the
    simulator's default (the same numbers: a test holds them equal)."""
    pos_threshold: float = 0.2     # nominal ON contrast threshold, log intensity
    neg_threshold: float = 0.2     # nominal OFF contrast threshold, log intensity
    threshold_sigma: float = 0.0   # pixel-to-pixel spread of the thresholds
    refractory_us: float = 0.0     # a pixel's dead time after an event, microseconds
    log_mode: str = "log"          # response: log(I + log_eps), or linlog (linear below linlog_threshold_dn)
    log_eps: float = 1e-3          # linear intensity added before the log
    linlog_threshold_dn: float = 20.0   # linlog: digital numbers where the response turns logarithmic
    linlog_dn_per_unit: float = 255.0   # linlog: digital numbers per unit of linear intensity
    fields: Mapping[str, Any] = field(default_factory=dict, compare=False)   # every stored parameter

    def __post_init__(self):
        if self.log_mode not in ("log", "linlog"):
            raise ValueError(f"log_mode: expected log or linlog, got {self.log_mode!r}")
        for name in ("pos_threshold", "neg_threshold", "linlog_threshold_dn", "linlog_dn_per_unit"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: expected a finite number > 0, got {v!r}")
        for name in ("threshold_sigma", "refractory_us", "log_eps"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name}: expected a finite number >= 0, got {v!r}")
        object.__setattr__(self, "fields", MappingProxyType(dict(self.fields)))

    @classmethod
    def from_fields(cls, data: Mapping[str, Any]) -> "SensorRecord":
        """The record of stored parameters (unknown names kept in `fields` only)."""
        named = {k: data[k] for k in NAMED if k in data}
        return cls(**named, fields=data)
