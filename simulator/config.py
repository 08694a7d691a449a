"""Simulator configuration: a frozen dataclass; every effect is off unless its parameter enables it."""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Literal

from common.config import ConfigError, ConfigWarning


MIN_THRESHOLD = 0.01      # smallest contrast threshold (log units) accepted
MAX_RATE_HZ = 1e5         # largest per-pixel noise / leak event rate accepted


@dataclass(frozen=True)
class SimulatorConfig:
    """DVS pixel model parameters (v2e's model; names carry units).

    Defaults are the ideal, noise-free sensor: log(I + 1e-3) response, C+ = C- = 0.2, no mismatch.
    An effect runs only when its parameter enables it (rate > 0, cutoff > 0, period > 0, sigma > 0).
    """

    # Log response. "log": log(I + log_eps) (as ESIM). "linlog": v2e's lin-log on digital numbers
    # DN = linlog_dn_per_unit * I: linear (DN * log(thr)/thr) below thr = linlog_threshold_dn DN, log above.
    log_mode: Literal["log", "linlog"] = "log"
    log_eps: float = 1e-3  # log mode: linear intensity added before the log
    linlog_threshold_dn: float = 20.0  # linlog mode: digital numbers below which the response is linear
    linlog_dn_per_unit: float = 255.0  # linlog mode: digital numbers per unit of linear intensity

    # Contrast thresholds (log units) and per-pixel mismatch: C ~ Normal(C, sigma), clamped to >= min.
    pos_threshold: float = 0.2
    neg_threshold: float = 0.2  # nominal OFF contrast threshold, log units
    threshold_sigma: float = 0.0  # pixel-to-pixel spread of both thresholds (std, log units; 0: none)
    threshold_min: float = 0.01  # a pixel's thresholds are clamped to at least this

    # Photoreceptor low-pass (v2e): first-order IIR with cutoff scaled by intensity; 0 = off.
    lowpass_cutoff_hz: float = 0.0
    # Refractory period: after an event the pixel is blind and its reference follows the input; 0 = off.
    refractory_us: int = 0
    # Leak: reference drifts down at leak_rate_hz ON events per second (log-normal per-pixel spread).
    leak_rate_hz: float = 0.0
    leak_rate_sigma_decades: float = 0.1  # per-pixel spread of the leak rate (log-normal, decades)
    # Shot noise: Poisson ON+OFF events at this total rate per pixel in the dark (x0.25 at white, v2e).
    shot_noise_rate_hz: float = 0.0
    # Hot pixels: this fraction of pixels emits ON events as a Poisson process at hot_pixel_rate_hz.
    hot_pixel_fraction: float = 0.0
    hot_pixel_rate_hz: float = 0.0  # each hot pixel's ON event rate

    # Shot noise's share of ON events (v2e: half), its scale at white against the dark (v2e: 0.25: noise
    # depends on the light, more in dark pixels), and the per-pixel spread of its rate (log-normal,
    # decades; a fixed pattern, as the leak's).
    shot_noise_on_fraction: float = 0.5
    shot_noise_white_factor: float = 0.25  # shot noise at white against the dark (v2e: 0.25)
    shot_noise_sigma_decades: float = 0.0  # per-pixel spread of the shot-noise rate (log-normal, decades; 0: none)

    # ON and OFF threshold mismatch apart (log units): None takes threshold_sigma (one sigma for both).
    pos_threshold_sigma: float | None = None
    neg_threshold_sigma: float | None = None  # OFF threshold spread (None: threshold_sigma)
    # Readout (simulator.readout), after the pixels: each event reaches the output latency_us later,
    # plus a jitter drawn from Normal(0, latency_jitter_us) truncated at +-3 sigma (never before the
    # crossing); a semi-synchronous readout reports timestamps in steps of readout_period_us (rounded up);
    # a bandwidth limit serves at most max_event_rate_hz events per second in arrival order (a FIFO):
    # an event waits for the ones before it, and is dropped when its wait would exceed max_readout_delay_us
    # (0: never dropped). 0 = off for each.
    latency_us: float = 0.0
    latency_jitter_us: float = 0.0  # std of the latency's jitter, truncated at +-3 sigma (0: none)
    readout_period_us: int = 0  # semi-synchronous readout: timestamps rounded up to this step (0: asynchronous)
    max_event_rate_hz: float = 0.0  # bandwidth limit of the readout, events per second (0: unlimited)
    max_readout_delay_us: int = 0  # an event waiting longer than this is dropped (0: never)
    # Noise with memory (DVS-Voltmeter's drift-diffusion pixel): a random walk with drift added to the
    # log input, whose threshold crossings are the pixel's own events. An event moves the reference and
    # the next needs a whole threshold of walk, so the intervals are more regular than Poisson (a renewal
    # process; coefficient of variation sqrt(2/3) without drift). Set by the event rate it makes on a
    # still pixel at the nominal thresholds (exact for C+ = C-, with the mean threshold otherwise), its
    # ON share (the drift) and the per-pixel spread of that rate (log-normal, decades; a fixed pattern).
    diffusion_noise_rate_hz: float = 0.0
    diffusion_noise_on_fraction: float = 0.5  # share of ON events on a still pixel (0.5: no drift)
    diffusion_noise_sigma_decades: float = 0.0  # per-pixel spread of the diffusion-noise rate (log-normal, decades)

    def __post_init__(self):
        def need(ok: bool, field: str, what: str):
            if not ok:
                raise ConfigError(f"{field}: expected {what}, got {getattr(self, field)!r}")

        finite = lambda v: isinstance(v, (int, float)) and math.isfinite(v)  # noqa: E731
        need(self.log_mode in ("log", "linlog"), "log_mode", "'log' or 'linlog'")
        need(finite(self.log_eps) and self.log_eps > 0, "log_eps", "a positive number")
        need(finite(self.linlog_threshold_dn) and self.linlog_threshold_dn > 1, "linlog_threshold_dn", "a number > 1")
        need(finite(self.linlog_dn_per_unit) and self.linlog_dn_per_unit > 0, "linlog_dn_per_unit", "a positive number")
        # a contrast threshold C lets a pixel fire up to (log range) / C events per frame: below MIN_THRESHOLD
        # one bright frame could ask for billions of events and exhaust memory instead of failing clearly
        need(finite(self.threshold_min) and self.threshold_min >= MIN_THRESHOLD, "threshold_min",
             f"a number >= {MIN_THRESHOLD} (1 % contrast; real sensors are ~10-50 %)")
        for name in ("pos_threshold", "neg_threshold"):
            need(finite(getattr(self, name)) and getattr(self, name) >= self.threshold_min, name,
                 f"a number >= threshold_min ({self.threshold_min})")
        for name in ("threshold_sigma", "lowpass_cutoff_hz", "leak_rate_hz", "leak_rate_sigma_decades",
                     "shot_noise_rate_hz", "hot_pixel_rate_hz", "diffusion_noise_rate_hz",
                     "diffusion_noise_sigma_decades"):
            need(finite(getattr(self, name)) and getattr(self, name) >= 0, name, "a non-negative number")
        for name in ("shot_noise_rate_hz", "hot_pixel_rate_hz", "leak_rate_hz", "diffusion_noise_rate_hz"):
            need(getattr(self, name) <= MAX_RATE_HZ, name, f"at most {MAX_RATE_HZ:g} events per second per pixel "
                 "(the sensor's bandwidth; more would only fill memory)")
        need(isinstance(self.refractory_us, int) and self.refractory_us >= 0, "refractory_us", "a non-negative integer")
        for name in ("pos_threshold_sigma", "neg_threshold_sigma"):
            need(getattr(self, name) is None or (finite(getattr(self, name)) and getattr(self, name) >= 0), name,
                 "a non-negative number, or null (threshold_sigma)")
        need(finite(self.shot_noise_on_fraction) and 0 <= self.shot_noise_on_fraction <= 1, "shot_noise_on_fraction",
             "a number in [0, 1]")
        # all-ON or all-OFF would need an infinite drift
        need(finite(self.diffusion_noise_on_fraction) and 0.001 <= self.diffusion_noise_on_fraction <= 0.999,
             "diffusion_noise_on_fraction", "a number in [0.001, 0.999]")
        for name in ("latency_us", "latency_jitter_us", "max_event_rate_hz", "shot_noise_white_factor",
                     "shot_noise_sigma_decades"):
            need(finite(getattr(self, name)) and getattr(self, name) >= 0, name, "a non-negative number")
        for name in ("readout_period_us", "max_readout_delay_us"):
            need(isinstance(getattr(self, name), int) and getattr(self, name) >= 0, name, "a non-negative integer")
        need(finite(self.hot_pixel_fraction) and 0 <= self.hot_pixel_fraction <= 1, "hot_pixel_fraction", "a number in [0, 1]")
        if max(self.sigma_pos, self.sigma_neg) > 0.5 * min(self.pos_threshold, self.neg_threshold):
            warnings.warn(f"threshold_sigma: {max(self.sigma_pos, self.sigma_neg)} is more than half the contrast threshold "
                          f"({min(self.pos_threshold, self.neg_threshold)}): many pixels' thresholds are clamped to "
                          f"threshold_min ({self.threshold_min}) and fire far more events (v2e's default sigma is "
                          "0.03)", ConfigWarning, stacklevel=3)

    # Which optional stages run.
    @property
    def sigma_pos(self) -> float:
        """The ON thresholds' per-pixel spread (log units)."""
        return self.threshold_sigma if self.pos_threshold_sigma is None else self.pos_threshold_sigma

    @property
    def sigma_neg(self) -> float:
        """The OFF thresholds' per-pixel spread (log units)."""
        return self.threshold_sigma if self.neg_threshold_sigma is None else self.neg_threshold_sigma

    @property
    def has_mismatch(self) -> bool:
        return self.sigma_pos > 0 or self.sigma_neg > 0

    @property
    def has_readout(self) -> bool:
        """Whether events pass a readout stage (latency, jitter, semi-synchronous steps, bandwidth)."""
        return bool(self.latency_us > 0 or self.latency_jitter_us > 0 or self.readout_period_us > 0
                    or self.max_event_rate_hz > 0)

    @property
    def has_lowpass(self) -> bool:
        return self.lowpass_cutoff_hz > 0

    @property
    def has_leak(self) -> bool:
        return self.leak_rate_hz > 0

    @property
    def has_shot_noise(self) -> bool:
        return self.shot_noise_rate_hz > 0

    @property
    def has_diffusion_noise(self) -> bool:
        return self.diffusion_noise_rate_hz > 0

    @property
    def has_hot_pixels(self) -> bool:
        return self.hot_pixel_fraction > 0 and self.hot_pixel_rate_hz > 0

    @property
    def is_noise_free(self) -> bool:
        """No random events (shot noise, hot pixels, diffusion noise); leak, mismatch, low-pass, refractory
        are deterministic."""
        return not (self.has_shot_noise or self.has_hot_pixels or self.has_diffusion_noise)

    def sensor_record(self):
        """This sensor as the plain record an event file holds (eventio.sensor.SensorRecord)."""
        from dataclasses import asdict

        from eventio.sensor import SensorRecord

        return SensorRecord.from_fields(asdict(self))


# Ranges of the numeric fields (common.config.check_bounds: refused when loaded, naming the key).
SimulatorConfig.BOUNDS = {
    "log_eps": (0.0, 1.0, "linear intensity"), "linlog_threshold_dn": (0.0, 65535.0, "digital numbers"),
    "linlog_dn_per_unit": (1e-6, 65535.0, "digital numbers per linear unit"),
    "pos_threshold": (0.0, 10.0, "log intensity"), "neg_threshold": (0.0, 10.0, "log intensity"),
    "threshold_sigma": (0.0, 10.0, "log intensity"), "threshold_min": (0.0, 10.0, "log intensity"),
    "lowpass_cutoff_hz": (0.0, 1e7, "Hz"), "refractory_us": (0, 10 ** 9, "microseconds (1000 s)"),
    "leak_rate_hz": (0.0, MAX_RATE_HZ, "events per second a pixel"), "leak_rate_sigma_decades": (0.0, 10.0, "decades"),
    "shot_noise_rate_hz": (0.0, MAX_RATE_HZ, "events per second a pixel"), "hot_pixel_fraction": (0.0, 1.0, "a fraction of the pixels"),
    "hot_pixel_rate_hz": (0.0, MAX_RATE_HZ, "events per second a pixel"),
    "shot_noise_on_fraction": (0.0, 1.0, "a fraction of the shot-noise events"),
    "shot_noise_white_factor": (0.0, 100.0, "a multiple of the dark rate"), "shot_noise_sigma_decades": (0.0, 10.0, "decades"),
    "pos_threshold_sigma": (0.0, 10.0, "log intensity"), "neg_threshold_sigma": (0.0, 10.0, "log intensity"),
    "latency_us": (0.0, 1e6, "microseconds"), "latency_jitter_us": (0.0, 1e6, "microseconds"),
    "readout_period_us": (0, 10 ** 6, "microseconds"), "max_event_rate_hz": (0.0, 1e10, "events per second (the sensor)"),
    "max_readout_delay_us": (0, 10 ** 9, "microseconds"),
    "diffusion_noise_rate_hz": (0.0, MAX_RATE_HZ, "events per second a pixel"),
    "diffusion_noise_on_fraction": (0.001, 0.999, "a fraction of the diffusion-noise events"),
    "diffusion_noise_sigma_decades": (0.0, 10.0, "decades"),
}

# Fields added after datasets were first written: left out of a scene's fingerprint at these values
# (off), so folders generated before them keep their identity (datagen.scene_folder.config_fingerprint).
LATER_FIELDS = {"shot_noise_on_fraction": 0.5, "shot_noise_white_factor": 0.25, "shot_noise_sigma_decades": 0.0,
                "pos_threshold_sigma": None, "neg_threshold_sigma": None, "latency_us": 0.0, "latency_jitter_us": 0.0,
                "readout_period_us": 0, "max_event_rate_hz": 0.0, "max_readout_delay_us": 0,
                "diffusion_noise_rate_hz": 0.0, "diffusion_noise_on_fraction": 0.5, "diffusion_noise_sigma_decades": 0.0}
