"""Event streams and event files: the typed stream at the centre, and every file format it is
read from or written to (no simulation here; `simulator/` builds on it).

    from eventio import EventStream, EventFile, read_recording, write_stream, read_events
    stream, fmt = read_recording("recording.aedat4")     # any supported format, detected
    write_stream("cam0.raw", stream, "evt3")               # h5, aedat4, evt3, evt2, rosbag, ros2bag, npz, txt

Modules: `events` (EVENT_DTYPE, EventStream, validation), `h5io` (our HDF5 files, DSEC layout),
`event_file` (EventFile: validated, windowed reads), `event_check`, `evt_codec` (Prophesee EVT 2.0 /
3.0), `vendor_formats` (AEDAT4 and the vendors' readers), `rosbag_io` / `ros_messages` (ROS1 / ROS2
bags), `export` (.npz, E2VID text), `formats` (one table of formats: detect, read, write).
"""
import common  # noqa: F401  (first: it sets the OpenMP wait policy before torch or numba loads)
from eventio.event_file import EventFile
from eventio.events import EVENT_DTYPE, EventStream, EventValidationError, empty_events, make_events, to_torch, validate_events
from eventio.formats import detect_format, read_recording, write_stream
from eventio.h5io import EventFileError, read_events, read_window, write_events

__all__ = ["EVENT_DTYPE", "EventFile", "EventFileError", "EventStream", "EventValidationError", "detect_format",
           "empty_events", "make_events", "read_events", "read_recording", "read_window", "to_torch",
           "validate_events", "write_events", "write_stream"]
