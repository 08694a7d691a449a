"""deforming: a board whose vertices move (an animated shape key), not its object transform.

Not part of the dataset: the tests check that the blur measurement, which tracks rigidly moving
parts, refuses it instead of measuring it wrong.
"""
from blender_scenes import common as C
from blender_scenes.common import frame_of


def build(cfg) -> None:
    from blender_scenes import textures as T

    board = C.box("board", (0.02, 2.0, 2.0), (0.0, 0.0, 1.0), C.material("checker", T.checker(64, 8, (0.2, 0.2, 0.2), (0.9, 0.9, 0.9))))
    board.shape_key_add(name="Basis")
    bent = board.shape_key_add(name="bent")
    for v in bent.data:
        v.co.x += 0.5 * v.co.y
    for value, tau in ((0.0, 0.0), (1.0, 1.0)):
        bent.value = value
        bent.keyframe_insert("value", frame=frame_of(tau))
