"""blur_plane_deform: blur_plane's board, moved by a shape key instead of its object transform.

Not part of the dataset: a test of the blur measurement on deforming meshes. The object never moves;
a shape key whose value goes linearly from 0 to 1 over the clip carries every vertex TRAVEL_M along
y, so the mesh translates exactly as blur_plane's board does and must give the same blur.
"""
from blender_scenes import blur_plane as B
from blender_scenes import common as C
from blender_scenes.common import _fcurves, frame_of


def build(cfg) -> None:
    from blender_scenes import textures as T

    face = C.box("face", (B.THICKNESS_M, 20.0, 10.0), (0.0, -B.TRAVEL_M / 2, 1.0),
                 C.material("checker", T.checker(64, 8, (0.2, 0.2, 0.2), (0.9, 0.9, 0.9))), tex_scale=1.0)
    face.shape_key_add(name="Basis")
    slide = face.shape_key_add(name="slide")
    for v in slide.data:
        v.co.y += B.TRAVEL_M
    for value, tau in ((0.0, 0.0), (1.0, 1.0)):
        slide.value = value
        slide.keyframe_insert(data_path="value", frame=frame_of(tau))
    for fc in _fcurves(face.data.shape_keys.animation_data.action):
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"
