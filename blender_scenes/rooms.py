"""Shared shell of the indoor scenes: floor and four walls (no ceiling, so the world-space studio
light reaches the floor), centred on the origin."""
from blender_scenes import common as C


def shell(half_x: float, half_y: float, height: float, floor_mat, wall_mats, thickness: float = 0.2,
          floor_tex: float = 2.0, wall_tex: float = 2.0) -> None:
    C.box("floor", (2 * half_x, 2 * half_y, thickness), (0, 0, -thickness / 2), floor_mat, tex_scale=floor_tex)
    walls = [("wall_n", (2 * half_x, thickness, height), (0, half_y, height / 2)),
             ("wall_s", (2 * half_x, thickness, height), (0, -half_y, height / 2)),
             ("wall_e", (thickness, 2 * half_y, height), (half_x, 0, height / 2)),
             ("wall_w", (thickness, 2 * half_y, height), (-half_x, 0, height / 2))]
    for (name, size, loc), mat in zip(walls, wall_mats):
        C.box(name, size, loc, mat, tex_scale=wall_tex)
