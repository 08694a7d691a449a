"""The stateful DVS simulator: frames in, events out, one sensor per instance.

`EventSimulator(config, width, height, seed).push(frame, t_us)` takes a linear-light frame
([H,W] luminance, or [H,W,3] linear RGB reduced with Rec.709 luma) and returns the events since the
previous frame as an `EVENT_DTYPE` array. The first frame only initialises the pixels.
`simulate(frames, t_us, config)` runs a whole sequence into an `EventStream`.

Stages, each run only when the config enables it: log response -> photoreceptor low-pass -> leak
(drift of the reference, applied as a rising offset on the input so the interval stays linear) ->
diffusion noise (a random walk with drift on the input, stepped at each frame) ->
shot noise and hot pixels (random events) -> threshold crossings with per-pixel mismatch,
refractory period and exact per-crossing timestamps (`kernels.emit_events`) -> the readout
(latency and jitter, semi-synchronous timestamps, bandwidth limit; `readout.Readout`), which may hold
events past the interval's end: `flush()` releases them after the last frame.
"""
from __future__ import annotations

import json
from typing import Iterable, Mapping, Sequence

import numpy as np

from common.config import to_dict
from simulator import pixel
from simulator.config import SimulatorConfig
from eventio.events import EventStream, empty_events
from simulator.kernel_ref import emit_events_ref
from simulator.kernels import Workspace, emit_events
from simulator.noise import NO_NOISE, draw_noise_events
from simulator.readout import Readout

_NEVER_US = np.iinfo(np.int64).min // 4  # "no event yet" for the refractory clock
BACKENDS = {"fast": emit_events, "ref": emit_events_ref}


class FrameError(ValueError):
    """A frame or its timestamp cannot be simulated (shape, values, time order)."""


MAX_PIXELS = 4096 * 4096       # the per-pixel state of ~30 arrays stays within a few GB


def _config_key(config: SimulatorConfig) -> dict:
    """A config as a checkpoint records it: fields added later are left out at their off value, so a
    run checkpointed before they existed resumes with the same sensor."""
    from simulator.config import LATER_FIELDS

    return {k: v for k, v in to_dict(config).items() if not (k in LATER_FIELDS and v == LATER_FIELDS[k])}


class EventSimulator:
    """Per-pixel state of one DVS sensor; see module docstring for the model."""

    def __init__(self, config: SimulatorConfig, width: int, height: int, seed: int = 0,
                 backend: str = "fast", threads: int | None = None):
        if backend not in BACKENDS:
            raise ValueError(f"backend must be one of {sorted(BACKENDS)}, got {backend!r}")
        if not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in (width, height)) \
                or width <= 0 or height <= 0:
            raise ValueError(f"sensor size must be positive integers, got {width!r} x {height!r}")
        if int(width) * int(height) > MAX_PIXELS:
            raise ValueError(f"sensor size {width} x {height} = {int(width) * int(height):,} pixels: more than "
                             f"{MAX_PIXELS:,} (4096 x 4096); the per-pixel state would not fit in memory")
        self.config, self.width, self.height, self.seed = config, int(width), int(height), int(seed)
        self._emit = BACKENDS[backend]
        # threads: work chunks of the fast kernel (default: numba's thread count; 1 for small sensors,
        # where the parallel kernel's overhead dominates)
        self._emit_kwargs = {"workspace": Workspace(threads)} if backend == "fast" else {}
        P = self.n_pixels = self.width * self.height
        # Independent streams: fixed-pattern parameters, then temporal noise.
        fixed_rng, self._noise_rng, readout_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3))
        c = config
        # thresholds: [P] with mismatch, [1] (shared by all pixels) without
        n_c = P if c.has_mismatch else 1
        self.c_pos = pixel.sample_thresholds(fixed_rng, c.pos_threshold, c.sigma_pos, c.threshold_min, n_c)
        self.c_neg = pixel.sample_thresholds(fixed_rng, c.neg_threshold, c.sigma_neg, c.threshold_min, n_c)
        self._leak_rates_hz = None
        self._leak_phase = None
        if c.has_leak:
            decades = fixed_rng.normal(0.0, c.leak_rate_sigma_decades, P) if c.leak_rate_sigma_decades > 0 else 0.0
            self._leak_rates_hz = c.leak_rate_hz * 10.0 ** decades * np.ones(P)
            self._leak_phase = fixed_rng.random(P)  # desynchronises leak events across pixels
            self._leak_step_per_s = self._leak_rates_hz * self.c_pos  # reference drift, log units / s
        self.hot_pixels = None
        if c.has_hot_pixels:
            n_hot = int(round(c.hot_pixel_fraction * P))
            self.hot_pixels = np.sort(fixed_rng.choice(P, size=n_hot, replace=False)).astype(np.int64)
        self._shot_gain = None          # per-pixel shot-noise rate factor (fixed pattern), drawn last
        if c.has_shot_noise and c.shot_noise_sigma_decades > 0:
            self._shot_gain = 10.0 ** fixed_rng.normal(0.0, c.shot_noise_sigma_decades, P)
        self._walk_sigma = self._walk_drift = None   # diffusion noise: per-pixel walk (drawn after the shot gain)
        if c.has_diffusion_noise:
            decades = fixed_rng.normal(0.0, c.diffusion_noise_sigma_decades, P) if c.diffusion_noise_sigma_decades > 0 else 0.0
            self._walk_sigma, self._walk_drift = pixel.diffusion_walk(
                c.diffusion_noise_rate_hz * 10.0 ** decades * np.ones(P), c.diffusion_noise_on_fraction,
                c.pos_threshold, c.neg_threshold)
            # the walk's start against the reference: a sensor switched on long before (stationary); a leak
            # beside it is more upward drift (its own start, the leak's phase, is then this one's limit)
            k = np.full(P, pixel.drift_number(c.diffusion_noise_on_fraction))
            if c.has_leak:
                c_mean = 0.5 * (c.pos_threshold + c.neg_threshold)
                k += 2.0 * self._leak_step_per_s * c_mean / self._walk_sigma ** 2
            self._walk_start = pixel.diffusion_equilibrium_offsets(fixed_rng, k)
        self.t_prev_us: int | None = None
        self.n_frames = 0
        self._log_bufs: dict[np.dtype, list[np.ndarray]] = {}
        self._linlog_scratch: dict[np.dtype, np.ndarray] = {}
        if c.has_lowpass or c.has_leak or c.has_diffusion_noise:
            self._level_bufs = [np.empty(P), np.empty(P)]
            self._scratch = np.empty(P)
        self._lp = self._leak_offset = self._walk = None
        # latency, jitter, semi-synchronous steps, bandwidth: after the pixels (simulator.readout)
        self.readout = Readout(config, readout_rng, backend) if config.has_readout else None

    # -- input checks -----------------------------------------------------------------------
    def _prepare(self, frame, t_us) -> tuple[np.ndarray, int]:
        where = f"frame {self.n_frames} (t={t_us} us)"
        if isinstance(t_us, (bool, np.bool_)) or not isinstance(t_us, (int, np.integer)):
            raise FrameError(f"{where}: timestamp must be an integer number of microseconds, got {type(t_us).__name__}")
        t_us = int(t_us)
        if self.t_prev_us is not None and t_us <= self.t_prev_us:
            raise FrameError(f"{where}: timestamps must increase, got {t_us} us after {self.t_prev_us} us")
        frame = np.asarray(frame)
        if not np.issubdtype(frame.dtype, np.floating):
            raise FrameError(f"{where}: expected a linear-light float frame, got dtype {frame.dtype} "
                             "(8-bit images are sRGB: linearise them with simulator.pixel.srgb_to_linear)")
        if frame.ndim == 3 and frame.shape[2] in (3, 4):
            frame = pixel.rec709_luma(frame[..., :3])
        elif frame.ndim == 3 and frame.shape[2] == 1:
            frame = frame[..., 0]
        if frame.shape != (self.height, self.width):
            raise FrameError(f"{where}: frame size {frame.shape} does not match the sensor "
                             f"(height, width) = ({self.height}, {self.width})")
        lo, hi = frame.min(), frame.max()
        if not (lo >= 0 and hi < np.inf):
            bad = ~(np.isfinite(frame) & (frame >= 0))
            r, col = np.argwhere(bad)[0]
            raise FrameError(f"{where}: intensities must be finite and >= 0, got {frame[r, col]} at (row {r}, col {col})")
        return frame.reshape(-1), t_us

    def _log(self, frame_flat: np.ndarray) -> np.ndarray:
        """Log response in the frame's own precision (float32 frames: float32 logs, float64: float64).

        Two buffers per dtype alternate, so the previous frame's level stays valid without copies.
        """
        c = self.config
        dtype = np.float32 if frame_flat.dtype == np.float32 else np.float64
        bufs = self._log_bufs.setdefault(np.dtype(dtype), [np.empty(self.n_pixels, dtype) for _ in range(2)])
        out = bufs[self.n_frames % 2]
        frame_flat = frame_flat.astype(dtype, copy=False)
        if c.log_mode == "log":
            return pixel.log_response(frame_flat, dtype(c.log_eps), out=out)
        scratch = self._linlog_scratch.get(np.dtype(dtype))
        if scratch is None:
            scratch = self._linlog_scratch[np.dtype(dtype)] = np.empty((2, self.n_pixels), dtype)
        return pixel.linlog_response(frame_flat, c.linlog_threshold_dn, c.linlog_dn_per_unit, out=out,
                                     scratch=scratch)

    # -- simulation -------------------------------------------------------------------------
    def push(self, frame: np.ndarray, t_us: int) -> np.ndarray:
        """Feed the frame at t_us; return the events in (previous frame time, t_us] (EVENT_DTYPE). The first
        frame only sets every pixel's reference level, so its call returns no events."""
        frame, t_us = self._prepare(frame, t_us)
        c = self.config
        log_now = self._log(frame)
        if self.t_prev_us is None:
            self._init_state(log_now)
            self.t_prev_us, self.n_frames = t_us, 1
            return empty_events()
        dt_s = (t_us - self.t_prev_us) * 1e-6
        level = log_now
        if c.has_lowpass or c.has_leak or c.has_diffusion_noise:
            level = self._level_bufs[self.n_frames % 2]  # the previous level stays in the other one
            if c.has_lowpass:
                pixel.lowpass_step(self._lp, log_now, frame, dt_s, c.lowpass_cutoff_hz, out=self._lp,
                                   scratch=self._scratch)
                np.copyto(level, self._lp)
            else:
                np.copyto(level, log_now)
            if c.has_leak:
                np.multiply(self._leak_step_per_s, dt_s, out=self._scratch)
                self._leak_offset += self._scratch
                level += self._leak_offset
            if c.has_diffusion_noise:   # the walk's step over dt: drift dt + sigma sqrt(dt) N(0, 1), linear between frames
                self._noise_rng.standard_normal(out=self._scratch)
                self._scratch *= self._walk_sigma
                self._scratch *= dt_s ** 0.5
                self._walk += self._scratch
                np.multiply(self._walk_drift, dt_s, out=self._scratch)
                self._walk += self._scratch
                level += self._walk
        noise = NO_NOISE
        if not c.is_noise_free:
            noise = draw_noise_events(self._noise_rng, self.t_prev_us, t_us, self.n_pixels, frame,
                                      c.shot_noise_rate_hz, (c.pos_threshold, c.neg_threshold),
                                      self.c_pos, self.c_neg, self.hot_pixels, c.hot_pixel_rate_hz,
                                      c.shot_noise_on_fraction, c.shot_noise_white_factor, self._shot_gain)
        events = self._emit(self._level, level, self._base, self._t_ready, self.c_pos, self.c_neg,
                            self.t_prev_us, t_us, c.refractory_us, *noise, self.width, **self._emit_kwargs)
        self._level = level
        self.t_prev_us = t_us
        self.n_frames += 1
        return events if self.readout is None else self.readout.push(events, t_us)

    def flush(self) -> np.ndarray:
        """The events still inside the readout at the end of the recording (none without a readout
        stage): call once after the last `push`."""
        return empty_events() if self.readout is None else self.readout.flush()

    def _init_state(self, log_now: np.ndarray) -> None:
        c = self.config
        P = self.n_pixels
        self._lp = log_now.astype(np.float64) if c.has_lowpass else None
        self._leak_offset = np.zeros(P) if c.has_leak else None
        self._walk = np.zeros(P) if c.has_diffusion_noise else None
        self._level = log_now  # input level at the previous frame (after low-pass and leak)
        self._base = log_now.astype(np.float64)
        if c.has_diffusion_noise:   # offsets in thresholds of each pixel's own side (the leak's included)
            start = self._walk_start
            self._base -= np.where(start > 0, start * self.c_pos, start * self.c_neg)
        elif c.has_leak:
            self._base -= self._leak_phase * self.c_pos
        self._t_ready = np.full(P, _NEVER_US, np.int64)

    # -- checkpoints ------------------------------------------------------------------------
    _STATE_ARRAYS = ("_level", "_base", "_t_ready", "_lp", "_leak_offset", "_walk")

    def state_dict(self) -> dict:
        """Everything needed to continue this sensor later: a dict of arrays and scalars.

        Fixed-pattern parameters (thresholds, leak rates, hot pixels) are not stored: they are
        regenerated from the seed, and `load_state_dict` checks that seed, size and config match.
        """
        state = {"width": self.width, "height": self.height, "seed": self.seed,
                 "config": json.dumps(_config_key(self.config), sort_keys=True), "n_frames": self.n_frames,
                 "t_prev_us": 0 if self.t_prev_us is None else self.t_prev_us,
                 "noise_rng": json.dumps(self._noise_rng.bit_generator.state)}
        if self.t_prev_us is not None:
            for name in self._STATE_ARRAYS:
                value = getattr(self, name)
                if value is not None:
                    state[name] = value.copy()
            if self.readout is not None:
                state.update(self.readout.state())
        return state

    def load_state_dict(self, state: Mapping) -> None:
        """Continue from `state_dict()` of a simulator built with the same config, size and seed."""
        mine = self.state_dict()
        for key in ("width", "height", "seed", "config"):
            if str(state[key]) != str(mine[key]):
                raise ValueError(f"simulator state does not match this simulator: {key} is {state[key]} "
                                 f"in the state, {mine[key]} here")
        self.n_frames = int(state["n_frames"])
        self.t_prev_us = None if self.n_frames == 0 else int(state["t_prev_us"])
        self._noise_rng.bit_generator.state = json.loads(str(state["noise_rng"]))
        for name in self._STATE_ARRAYS:
            setattr(self, name, np.array(state[name]) if name in state else None)
        if self.readout is not None and "readout_pending" in state:
            self.readout.load_state(state)


def simulate(frames: Iterable[np.ndarray], t_us: Sequence[int], config: SimulatorConfig | None = None,
             seed: int = 0, backend: str = "fast") -> EventStream:
    """Simulate a whole frame sequence ([N,H,W] array or iterable of frames) into one EventStream."""
    config = config or SimulatorConfig()
    t_us = list(t_us)
    sim = None
    chunks = []
    n = 0
    for n, frame in enumerate(frames):
        if n >= len(t_us):
            raise FrameError(f"frame {n} has no timestamp: {len(t_us)} timestamps given")
        frame = np.asarray(frame)
        if sim is None:
            sim = EventSimulator(config, frame.shape[1], frame.shape[0], seed=seed, backend=backend)
        chunks.append(sim.push(frame, t_us[n]))
    if sim is None:
        raise FrameError("simulate: no frames given")
    chunks.append(sim.flush())
    if n + 1 != len(t_us):
        raise FrameError(f"simulate: {n + 1} frames but {len(t_us)} timestamps")
    return EventStream(np.concatenate(chunks), sim.width, sim.height)
