"""blur_plane_topology: blur_plane's board with an Array modifier whose count steps from 1 to 2 at mid-clip.

Not part of the dataset: the mesh's vertex count changes over the clip, so its surface points cannot
be tracked; the generator must refuse the scene, naming the part, before writing anything.
"""
from blender_scenes import blur_plane as B
from blender_scenes import common as C
from blender_scenes.common import frame_of


def build(cfg) -> None:
    from blender_scenes import textures as T

    face = C.box("face", (B.THICKNESS_M, 20.0, 10.0), (0.0, 0.0, 1.0),
                 C.material("checker", T.checker(64, 8, (0.2, 0.2, 0.2), (0.9, 0.9, 0.9))), tex_scale=1.0)
    arr = face.modifiers.new("array", "ARRAY")
    for count, tau in ((1, 0.0), (1, 0.49), (2, 0.5), (2, 1.0)):
        arr.count = count
        face.keyframe_insert(data_path='modifiers["array"].count', frame=frame_of(tau))
