"""A generated scene's cameras in other formats: one file per camera, or (ROS) one bag holding every
camera the way ESIM's bags do: events, camera info, poses and the sharp frames (topics in
eventio.rosbag_io)."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from common.fileio import atomic_output
from scene_format.cameras import rotmat_to_quat
from scene_format.reader import SceneDataset
from eventio import formats, rosbag_io
from eventio.h5io import read_events


def export_scene(scene_dir: str | os.PathLike, fmt: str, out: str | os.PathLike, message_us: int = 1000) -> list[Path]:
    """Every camera of a scene in format `fmt`: `out` is a folder of cam{k}<suffix> files, or for
    rosbag / rosbag2 the bag itself. Returns the written paths."""
    ds = SceneDataset(scene_dir)
    out = Path(out)
    streams = {f"/cam{k}/events": read_events(ds.event_file(k)) for k in range(ds.n_cameras)}
    if fmt in ("rosbag", "rosbag2"):
        return [rosbag_io.write_bag(out, streams, ros2=fmt == "rosbag2", message_us=message_us,
                                    extra=lambda w, store, ser: _scene_topics(ds, w, store, ser))]
    if out.exists():
        raise formats.FormatError(f"{out}: exists; the cameras' files go into a new folder")
    with atomic_output(out) as tmp:                             # complete, or not there at all
        tmp.mkdir()
        for k, s in enumerate(streams.values()):
            formats.write_stream(tmp / f"cam{k}{formats.SUFFIX[fmt]}", s, fmt)
    return sorted(out.iterdir())


def _scene_topics(ds: SceneDataset, writer, store, serialize) -> None:
    """camera_info once per camera, then pose and image_raw at every sharp frame (train and test)."""
    T = store.types
    ros2 = "seq" not in T["std_msgs/msg/Header"].__dataclass_fields__

    def header(t_us: int, frame: str):
        stamp = rosbag_io.ros_time(store, t_us)
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame) if ros2 else \
            T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)

    def add(topic, msgtype):
        return writer.add_connection(topic, msgtype, typestore=store)

    intr = ds.intrinsics
    K = np.asarray(intr.K, np.float64)
    records = sorted(ds.frames("train") + ds.frames("test"), key=lambda r: (r.camera, r.t_us))
    for k in range(ds.n_cameras):
        frame = f"cam{k}"
        Info = T["sensor_msgs/msg/CameraInfo"]
        matrices = {"d": np.zeros(5), "k": K.reshape(-1), "r": np.eye(3).reshape(-1),
                    "p": np.hstack([K, np.zeros((3, 1))]).reshape(-1)}
        # ROS1 spells the matrices D, K, R, P; ROS2 d, k, r, p
        matrices = {(n if n in Info.__dataclass_fields__ else n.upper()): v for n, v in matrices.items()}
        info = Info(header=header(0, frame), height=intr.height, width=intr.width, distortion_model="plumb_bob",
                    binning_x=0, binning_y=0, **matrices,
                    roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
        conn = add(f"/cam{k}/camera_info", "sensor_msgs/msg/CameraInfo")
        writer.write(conn, 0, serialize(info, "sensor_msgs/msg/CameraInfo"))
        pose_conn = add(f"/cam{k}/pose", "geometry_msgs/msg/PoseStamped")
        image_conn = add(f"/cam{k}/image_raw", "sensor_msgs/msg/Image")
        for rec in (r for r in records if r.camera == k):
            c2w = ds.pose(k, rec.t_us)
            q = rotmat_to_quat(c2w[:3, :3])                 # (w, x, y, z), w >= 0
            pose = T["geometry_msgs/msg/PoseStamped"](
                header=header(rec.t_us, "world"),
                pose=T["geometry_msgs/msg/Pose"](
                    position=T["geometry_msgs/msg/Point"](x=float(c2w[0, 3]), y=float(c2w[1, 3]), z=float(c2w[2, 3])),
                    orientation=T["geometry_msgs/msg/Quaternion"](x=float(q[1]), y=float(q[2]), z=float(q[3]), w=float(q[0]))))
            writer.write(pose_conn, rec.t_us * 1000, serialize(pose, "geometry_msgs/msg/PoseStamped"))
            rgb = np.round(ds.load_image(rec.path) * 255).astype(np.uint8)
            image = T["sensor_msgs/msg/Image"](header=header(rec.t_us, frame), height=rgb.shape[0], width=rgb.shape[1],
                                               encoding="rgb8", is_bigendian=0, step=rgb.shape[1] * 3,
                                               data=rgb.reshape(-1))
            writer.write(image_conn, rec.t_us * 1000, serialize(image, "sensor_msgs/msg/Image"))
