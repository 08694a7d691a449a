"""A scene folder's name: a scene or one of its speed variants (`garage_x4`: garage traversed 4x
faster, datagen.speed), and the blur level a variant's fixed shutter is stored under."""
from __future__ import annotations

import re

SHUTTER_LEVEL = "shutter"     # the blur level of a speed variant: its fixed real-time exposure
_VARIANT = re.compile(r"^(?P<scene>.+)_x(?P<speed>\d+(?:\.\d+)?)$")


def speed_label(speed: float) -> str:
    """'4' for 4.0, '2.5' for 2.5: how a speed appears in folder names and tables."""
    return f"{float(speed):g}"


def variant_name(scene: str, speed: float) -> str:
    """Folder name of a scene's speed variant: 'garage_x4'."""
    return f"{scene}_x{speed_label(speed)}"


def split_variant(name: str) -> tuple[str, float]:
    """(scene, speed) of a folder name: ('garage', 4.0) for 'garage_x4', (name, 1.0) for a plain scene."""
    m = _VARIANT.match(name)
    return (m["scene"], float(m["speed"])) if m else (name, 1.0)
