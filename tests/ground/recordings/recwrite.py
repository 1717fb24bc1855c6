"""Write RGB-D frames as the recordings other tools make: a TUM RGB-D folder, and ROS 1 and
ROS 2 bags through ``rosbags``' own writers (the formats the readers under test read)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
import numpy.typing as npt
from rosbags.typesys import Stores, get_typestore

from holescan.detect import CameraIntrinsics

Pair = tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint16]]  # RGB, depth mm
T0_NS = 1_305_031_102_175_304_000  # a TUM-like start time (2011)
PERIOD_NS = 33_333_333


def write_tum(folder: Path, frames: Sequence[Pair], depth_lag_ns: int = 4_000_000) -> Path:
    """A TUM folder: colour at 30 Hz, depth ``depth_lag_ns`` later, 5000 per metre, plus one
    extra colour image with no depth near it (the association must leave it out)."""
    (folder / "rgb").mkdir(parents=True)
    (folder / "depth").mkdir()
    rgb_lines = ["# color images", "# file: 'test'", "# timestamp filename"]
    depth_lines = ["# depth maps", "# file: 'test'", "# timestamp filename"]
    for i, (rgb, mm) in enumerate(frames):
        t_rgb = (T0_NS + i * PERIOD_NS) / 1e9
        t_d = (T0_NS + i * PERIOD_NS + depth_lag_ns) / 1e9
        cv2.imwrite(str(folder / f"rgb/{t_rgb:.6f}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        cv2.imwrite(
            str(folder / f"depth/{t_d:.6f}.png"), (mm.astype(np.uint32) * 5).astype(np.uint16)
        )
        rgb_lines.append(f"{t_rgb:.6f} rgb/{t_rgb:.6f}.png")
        depth_lines.append(f"{t_d:.6f} depth/{t_d:.6f}.png")
    t_lone = (T0_NS + len(frames) * PERIOD_NS + 500_000_000) / 1e9
    cv2.imwrite(
        str(folder / f"rgb/{t_lone:.6f}.png"), cv2.cvtColor(frames[0][0], cv2.COLOR_RGB2BGR)
    )
    rgb_lines.append(f"{t_lone:.6f} rgb/{t_lone:.6f}.png")
    (folder / "rgb.txt").write_text("\n".join(rgb_lines) + "\n")
    (folder / "depth.txt").write_text("\n".join(depth_lines) + "\n")
    return folder


def write_bag(
    path: Path,
    frames: Sequence[Pair],
    camera: CameraIntrinsics,
    version: Literal[1, 2],
    *,
    depth_encoding: Literal["16UC1", "32FC1"] = "16UC1",
    compressed_colour: bool = False,
    fix: tuple[float, float, float] | None = None,
) -> Path:
    """A ROS ``version`` bag: colour on /camera/rgb/image_color (bgr8, or JPEG-free PNG
    CompressedImage), registered depth on /camera/depth_registered/image_raw, raw depth of
    another size on /camera/depth/image_raw (must not be chosen), CameraInfo beside colour.
    ``fix`` (lat, lon, alt): MAVROS's NavSatFix at 10 Hz and Imu at 50 Hz (level, facing
    north) from 0.5 s before the first frame to 0.5 s after the last."""
    ts = get_typestore(Stores.ROS1_NOETIC if version == 1 else Stores.ROS2_HUMBLE)
    T = ts.types
    Image, Info = T["sensor_msgs/msg/Image"], T["sensor_msgs/msg/CameraInfo"]
    Compressed = T["sensor_msgs/msg/CompressedImage"]
    Time, Header, Roi = (
        T["builtin_interfaces/msg/Time"],
        T["std_msgs/msg/Header"],
        T["sensor_msgs/msg/RegionOfInterest"],
    )

    def header(t_ns: int, seq: int) -> Any:
        stamp = Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)
        if version == 1:
            return Header(seq=seq, stamp=stamp, frame_id="camera_rgb_optical_frame")
        return Header(stamp=stamp, frame_id="camera_rgb_optical_frame")

    def image(t_ns: int, seq: int, arr: npt.NDArray[Any], enc: str) -> Any:
        h, w = arr.shape[:2]
        data = np.ascontiguousarray(arr).view(np.uint8).reshape(-1)
        return Image(
            header=header(t_ns, seq),
            height=h,
            width=w,
            encoding=enc,
            is_bigendian=0,
            step=data.size // h,
            data=data,
        )

    k = [camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0]
    p = [camera.fx, 0.0, camera.cx, 0.0, 0.0, camera.fy, camera.cy, 0.0, 0.0, 0.0, 1.0, 0.0]
    eye = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    roi = Roi(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    arrays = {"d": np.zeros(5), "k": np.array(k), "r": np.array(eye), "p": np.array(p)}
    if version == 1:
        arrays = {key.upper(): v for key, v in arrays.items()}

    def info(t_ns: int, seq: int) -> Any:
        return Info(
            header=header(t_ns, seq),
            height=camera.height,
            width=camera.width,
            distortion_model="plumb_bob",
            binning_x=0,
            binning_y=0,
            roi=roi,
            **arrays,
        )

    if version == 1:
        from rosbags.rosbag1 import Writer as Writer1

        writer: Any = Writer1(path)
        serialize = ts.serialize_ros1
    else:
        from rosbags.rosbag2 import Writer as Writer2

        writer = Writer2(path, version=9)
        serialize = ts.serialize_cdr
    with writer:
        colour_type = Compressed if compressed_colour else Image
        c_col = writer.add_connection(
            "/camera/rgb/image_color", colour_type.__msgtype__, typestore=ts
        )
        c_reg = writer.add_connection(
            "/camera/depth_registered/image_raw", Image.__msgtype__, typestore=ts
        )
        c_raw = writer.add_connection("/camera/depth/image_raw", Image.__msgtype__, typestore=ts)
        c_info = writer.add_connection("/camera/rgb/camera_info", Info.__msgtype__, typestore=ts)
        if fix is not None:
            _write_pose(writer, ts, serialize, header, fix, len(frames))
        for i, (rgb, mm) in enumerate(frames):
            t = T0_NS + i * PERIOD_NS
            t_d = t + 3_000_000
            bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
            if compressed_colour:
                ok, png = cv2.imencode(".png", bgr)
                assert ok
                col: Any = Compressed(
                    header=header(t, i), format="bgr8; png compressed bgr8", data=png.reshape(-1)
                )
            else:
                col = image(t, i, bgr, "bgr8")
            if depth_encoding == "32FC1":
                metres = mm.astype(np.float32) / 1000.0
                metres[mm == 0] = np.nan
                reg = image(t_d, i, metres, "32FC1")
            else:
                reg = image(t_d, i, mm, "16UC1")
            raw = image(t_d, i, mm[::2, ::2].copy(), "16UC1")
            for conn, msg, when in (
                (c_info, info(t, i), t),
                (c_col, col, t),
                (c_reg, reg, t_d),
                (c_raw, raw, t_d),
            ):
                writer.write(conn, when, serialize(msg, conn.msgtype))
    return path


def _write_pose(
    writer: Any, ts: Any, serialize: Any, header: Any, fix: tuple[float, float, float], n: int
) -> None:
    T = ts.types
    NavSatFix, Status, Imu = (
        T["sensor_msgs/msg/NavSatFix"],
        T["sensor_msgs/msg/NavSatStatus"],
        T["sensor_msgs/msg/Imu"],
    )
    Quaternion, Vector3 = T["geometry_msgs/msg/Quaternion"], T["geometry_msgs/msg/Vector3"]
    c_fix = writer.add_connection(
        "/mavros/global_position/global", NavSatFix.__msgtype__, typestore=ts
    )
    c_imu = writer.add_connection("/mavros/imu/data", Imu.__msgtype__, typestore=ts)
    start, end = T0_NS - 500_000_000, T0_NS + n * PERIOD_NS + 500_000_000
    s45 = float(np.sqrt(0.5))
    zeros = np.zeros(9)
    msgs: list[tuple[int, Any, Any]] = []
    for k, t in enumerate(range(start, end, 100_000_000)):
        msg = NavSatFix(
            header=header(t, k),
            status=Status(status=0, service=1),
            latitude=fix[0],
            longitude=fix[1],
            altitude=fix[2],
            position_covariance=np.diag([0.25, 0.25, 1.0]).reshape(-1),
            position_covariance_type=2,
        )
        msgs.append((t, c_fix, msg))
    for k, t in enumerate(range(start, end, 20_000_000)):
        msg = Imu(
            header=header(t, k),
            orientation=Quaternion(x=0.0, y=0.0, z=s45, w=s45),
            orientation_covariance=zeros,
            angular_velocity=Vector3(x=0.0, y=0.0, z=0.0),
            angular_velocity_covariance=zeros,
            linear_acceleration=Vector3(x=0.0, y=0.0, z=9.81),
            linear_acceleration_covariance=zeros,
        )
        msgs.append((t, c_imu, msg))
    for t, conn, msg in sorted(msgs, key=lambda m: m[0]):
        writer.write(conn, t, serialize(msg, conn.msgtype))
