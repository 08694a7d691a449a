"""The readers on files real cameras wrote, against two independent decoders (faery, aedat): a
DAVIS346 AEDAT4 clip, an IMX636 (EVK4) EVT 3.0, a Gen3 VGA EVT 2.0 and a DVXplorer Lite AEDAT4 clip,
which live beside the checkout (../shared/reference/real-clips; too large or under LGPL / AGPL, so not
copied in: the tests that need one say so when it is absent)."""
import hashlib
from pathlib import Path

import numpy as np
import pytest

from eventio.formats import read_recording

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "reference" / "real-clips"
DAVIS346 = SHARED / "davis346_aedat-2.3.0.aedat4"
# file -> (format, width, height, events, ON fraction to 3 digits): the clips' README, measured independently
CLIPS = {"davis346": (DAVIS346, "aedat4", 346, 260, 78_830, 0.523),
         "imx636": (SHARED / "imx636_evk4_faery-0.7.1.raw", "evt3", 1280, 720, 1_218_618, 0.454),
         "gen3vga": (SHARED / "gen3vga_faery-0.7.1.raw", "evt2", 640, 480, 521_252, 0.357),
         "dvxplorer": (SHARED / "dvxplorer_lite_aermanager-0.3.0.aedat4", "aedat4", 320, 240, 323_963, 0.518)}


def _clip(name: str) -> Path:
    path = CLIPS[name][0]
    if not path.is_file():
        pytest.skip(f"{path} is absent: the {name} clip is LGPL / AGPL and not copied into the project; CI "
                    "and a checkout beside ../shared have it")
    return path


def test_the_davis346_clip_is_the_published_file():
    assert hashlib.sha256(_clip("davis346").read_bytes()).hexdigest() == \
        "b383462d72122c69fd96ebf095c384e3f1a2f092cc1b2681be52ebc1d260cf8a"


@pytest.mark.parametrize("name", list(CLIPS))
def test_a_real_clip_reads_exactly_as_faery_reads_it(name):
    import faery                  # a test dependency (pyproject [test]): a broken install fails here
    path = _clip(name)
    fmt, width, height, n, on = CLIPS[name][1:]
    stream, found = read_recording(path)
    e = stream.events
    assert found == fmt and (stream.width, stream.height) == (width, height)
    assert len(e) == n and round(float(np.mean(e["p"] > 0)), 3) == on
    theirs = np.concatenate(list(faery.events_stream_from_file(path)))
    assert len(theirs) == n
    np.testing.assert_array_equal(e["t"], theirs["t"].astype(np.int64))
    np.testing.assert_array_equal(e["x"], theirs["x"])
    np.testing.assert_array_equal(e["y"], theirs["y"])
    np.testing.assert_array_equal(e["p"], np.where(theirs["on"], 1, -1))
    assert int(e["x"].max()) < width and int(e["y"].max()) < height


@pytest.mark.parametrize("name", ["davis346", "dvxplorer"])
def test_an_aedat4_clip_reads_exactly_as_the_aedat_decoder_reads_it(name):
    import aedat                  # a test dependency (pyproject [test])
    path = _clip(name)
    stream, _ = read_recording(path)
    packets = [p["events"] for p in aedat.Decoder(str(path)) if "events" in p]
    theirs = np.concatenate(packets)
    e = stream.events
    np.testing.assert_array_equal(e["t"], theirs["t"].astype(np.int64))
    np.testing.assert_array_equal(e["x"], theirs["x"])
    np.testing.assert_array_equal(e["y"], theirs["y"])
    np.testing.assert_array_equal(e["p"], np.where(theirs["on"], 1, -1))


def test_a_header_that_names_only_its_plugin_gets_that_cameras_size():
    from eventio.evt_codec import parse_raw_header

    head = b"% Date 2020-09-25 07:48:31\n% plugin_name hal_plugin_gen3_fx3\n% evt 2.0\n"
    h = parse_raw_header(head + b"\x00" * 8)
    assert (h.fmt, h.width, h.height) == ("evt2", 640, 480)
    with pytest.raises(ValueError, match="no sensor size .* 'hal_plugin_unknown'"):
        parse_raw_header(head.replace(b"gen3_fx3", b"unknown") + b"\x00" * 8)
