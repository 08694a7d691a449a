"""tools.sensor_bandwidth: an edge's event count has its analytic value, and a photoreceptor low-pass
removes a fast grating's events only when its cutoff is below the grating's frequency."""
import math
from dataclasses import replace

from simulator.config import SimulatorConfig
from tools.sensor_bandwidth import (
    crossed_pixels,
    edge_frames,
    events_per_pixel,
    grating_frames,
    main,
)

SPEED, DURATION = 0.033, 3800.0          # px per us (33 px/ms), us


def test_an_edge_fires_floor_of_its_contrast_over_the_threshold_at_every_pixel_it_crosses():
    cfg = SimulatorConfig(pos_threshold=0.2, neg_threshold=0.2, threshold_sigma=0.0)
    n = events_per_pixel(cfg, edge_frames(SPEED, DURATION, 0.5, 0.05), crossed_pixels(SPEED, DURATION))
    assert n == math.floor(math.log(0.5 / 0.05) / 0.2)


def test_a_low_pass_removes_a_grating_above_its_cutoff_and_keeps_one_below():
    base = SimulatorConfig(pos_threshold=0.2, neg_threshold=0.2, threshold_sigma=0.0)
    plain = events_per_pixel(base, grating_frames(SPEED, DURATION))            # 4.1 kHz at each pixel
    slow = events_per_pixel(replace(base, lowpass_cutoff_hz=300.0), grating_frames(SPEED, DURATION))
    fast = events_per_pixel(replace(base, lowpass_cutoff_hz=1e6), grating_frames(SPEED, DURATION))
    assert plain > 50 and slow < plain / 20
    assert abs(fast - plain) / plain < 0.1


def test_the_tool_prints_its_table(capsys):
    assert main(["--sensor", "davis346", "--duration-us", "500"]) == 0
    out = capsys.readouterr().out
    assert "davis346 without its cutoff" in out and out.count("\n") == 5
