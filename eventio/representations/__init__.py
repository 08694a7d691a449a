"""What is drawn from events: one representation per module, each with a `>>>` example.

    count_image      events summed per pixel (signed, or ON and OFF apart)       count_image.py
    time_surface     exp(-age / tau) of each pixel's latest ON / OFF event         time_surface.py
    voxel_grid       B temporal bins with bilinear weights, as E2VID builds them   voxel_grid.py
    event_frame      an RGB picture: ON red, OFF blue (annotate, overlay_flow)     event_picture.py
    save_video       sliding windows (window_starts, parse_time_us) into an MP4    video.py

Used by e2vid (voxel grids), recon (count images), viewer and datagen (event pictures), and the
`e4dgs draw-events` command. NumPy only (OpenCV / ffmpeg imported where a picture is drawn or a video written).
"""
from eventio.representations.count_image import count_image
from eventio.representations.event_picture import annotate, event_frame, overlay_flow
from eventio.representations.time_surface import time_surface, time_surface_ref
from eventio.representations.video import parse_time_us, save_video, window_starts
from eventio.representations.voxel_grid import voxel_grid, voxel_grid_events, voxel_grid_ref

__all__ = ["annotate", "count_image", "event_frame", "overlay_flow", "parse_time_us", "save_video", "time_surface",
           "time_surface_ref", "voxel_grid", "voxel_grid_events", "voxel_grid_ref", "window_starts"]
