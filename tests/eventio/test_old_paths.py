"""The event-file modules moved from simulator/ to eventio/ in 0.2; the old names keep working
(the same module objects) with a deprecation line until 0.3."""
import importlib
import subprocess
import sys

import numpy as np
import pytest

MOVED = ["events", "event_check", "h5io", "evt_codec", "vendor_formats", "rosbag_io", "ros_messages", "export", "formats"]


@pytest.mark.parametrize("name", MOVED)
def test_an_old_module_name_is_the_new_module_and_warns(name):
    code = (f"import warnings; warnings.simplefilter('error', FutureWarning)\n"
            f"try:\n    import simulator.{name}\nexcept FutureWarning as w:\n    print('WARNED', w)\n"
            f"warnings.simplefilter('ignore')\nimport importlib, simulator.{name} as old, eventio.{name} as new\n"
            f"print('SAME', old is new)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert f"WARNED `simulator.{name}` moved to `eventio.{name}`" in out
    assert "SAME True" in out


def test_from_simulator_import_an_old_module_gives_the_new_one():
    import simulator

    sys.modules.pop("simulator.h5io", None)
    simulator.__dict__.pop("h5io", None)
    with pytest.warns(FutureWarning, match="eventio.h5io"):
        from simulator import h5io
    assert h5io is importlib.import_module("eventio.h5io")


def test_an_event_file_holds_a_plain_sensor_record_and_the_typed_config_reads_back(tmp_path):
    from eventio import EventFile, EventStream, make_events, write_events
    from eventio.h5io import EventFileError, simulator_attrs
    from eventio.sensor import SensorRecord
    from simulator import SimulatorConfig
    from simulator.event_file import sensor_of

    cfg = SimulatorConfig(pos_threshold=0.3, neg_threshold=0.25, refractory_us=500, threshold_sigma=0.05)
    ev = EventStream(make_events(np.array([5, 9]), np.array([1, 2]), np.array([0, 1]), np.array([1, -1])), 4, 3)
    path = tmp_path / "e.h5"
    write_events(path, ev, attrs=simulator_attrs(cfg))
    with EventFile(path) as f:
        assert f.sensor == cfg.sensor_record() == SensorRecord(0.3, 0.25, 0.05, 500, "log", 1e-3, 20.0, 255.0) and f.n == 2
        assert f.sensor.fields["refractory_us"] == 500 and sensor_of(f) == cfg
    # the record's defaults are the simulator's: a file that stores nothing reads as the default sensor
    assert SimulatorConfig().sensor_record() == SensorRecord()
    lin = SimulatorConfig(log_mode="linlog", linlog_threshold_dn=12.0)
    assert (lin.sensor_record().log_mode, lin.sensor_record().linlog_threshold_dn) == ("linlog", 12.0)
    bad = tmp_path / "bad.h5"
    write_events(bad, ev, attrs=simulator_attrs(cfg) | {"simulator_config": "pos_threshold: -1\n"})
    with EventFile(bad) as f, pytest.raises(EventFileError, match=r"bad.h5: the stored sensor is not valid \(pos_threshold"):
        f.sensor