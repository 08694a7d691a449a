"""blur_plane: a large textured board sliding sideways at constant speed in front of a fixed camera.

Not part of the dataset: the tests use it to check the geometric blur measurement against the
analytic answer. The board's front face is parallel to the image plane at depth FRONT_DEPTH_M
(camera at radius 4 on the x axis looking at the origin), and it moves along y by TRAVEL_M over the
clip, so every visible point moves fx * TRAVEL_M / (duration * FRONT_DEPTH_M) px per second.
"""
from blender_scenes import common as C

CAMERA_RADIUS_M = 4.0
THICKNESS_M = 0.02
FRONT_DEPTH_M = CAMERA_RADIUS_M - THICKNESS_M / 2
TRAVEL_M = 2.0


def build(cfg) -> None:
    from blender_scenes import textures as T

    board = C.pivot("board")
    C.box("face", (THICKNESS_M, 20.0, 10.0), (0.0, 0.0, 1.0), C.material("checker", T.checker(64, 8, (0.2, 0.2, 0.2), (0.9, 0.9, 0.9))),
          board, tex_scale=1.0)
    C.keyframes(board, "location", [(0.0, -TRAVEL_M / 2, 0.0), (0.0, TRAVEL_M / 2, 0.0)], [0.0, 1.0], "LINEAR")
