"""The `ros2` Camera: brightness from `camera/image_raw` (`sensor_msgs/msg/Image`), people from
`camera/detections` (`vision_msgs/msg/Detection2DArray`) (docs/ros2.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from components.ros2 import Ros2Driver
from drd.hosts import Device
from drd.hw.interfaces import DetectionLike, HardwareError
from drd.hw.ros2 import image_columns, strips


@dataclass(frozen=True, slots=True)
class Detection:
    """A person in view, as `DetectionLike` says: track label, bearing (rad, left positive), distance (m), light."""

    label: str
    bearing: float
    distance: float
    light: float


class Ros2Camera(Ros2Driver):
    """A ROS 2 camera and person detector. Options: `fov` (degrees, default 60), `resolution` (pixels across,
    default 640: the detector's image width, for a detection given only as a box). `driver_options`: `max_age`,
    `camera_frame`, `classes`, `topics: {image: ..., detections: ... or false}`."""

    READINGS = frozenset({"detections", "brightness", "fov", "resolution"})

    def __init__(self, device: Device, robot_id: str, backend: object = None) -> None:
        super().__init__(device, robot_id, backend)
        self.fov = math.radians(self.option("fov", 60.0))
        self.resolution = int(self.option("resolution", 640))
        frame = self.opts.frames.get("camera_frame")
        self._image = self.subscribe("image", self.opts.max_age, frame)
        self._detections = self.subscribe("detections", self.opts.max_age, frame)
        self._columns: tuple[Any, np.ndarray[Any, Any]] | None = None

    def columns(self) -> np.ndarray[Any, Any]:
        """The latest image's column brightness, left to right (computed once per image)."""
        assert self._image is not None
        msg = self._image.get()
        if self._columns is None or self._columns[0] is not msg:
            try:
                self._columns = (msg, image_columns(msg))
            except ValueError as e:
                raise HardwareError(f"{self.describe()}: {e}") from None
        return self._columns[1]

    def brightness(self, n_regions: int) -> list[float]:
        """Mean light of `n_regions` strips of the latest image (at most its width), right to left."""
        return strips(self.columns(), n_regions)

    def detections(self) -> list[DetectionLike]:
        """People in the latest detection array ([] when the options turn detections off)."""
        if self._detections is None:
            return []
        msg = self._detections.get()
        out: list[DetectionLike] = []
        for d in msg.detections:
            best = max(d.results, key=lambda r: r.hypothesis.score, default=None)
            if best is None or best.hypothesis.class_id not in self.opts.classes:
                continue
            p = best.pose.pose.position
            if p.x or p.y:
                bearing, distance = math.atan2(p.y, p.x), math.hypot(p.x, p.y)
            else:  # a box only: its centre through a pinhole of the camera's fov and width
                focal = self.resolution / 2 / math.tan(self.fov / 2)
                bearing, distance = math.atan2(self.resolution / 2 - d.bbox.center.position.x, focal), math.inf
            out.append(Detection(d.id or best.hypothesis.class_id, bearing, distance, self._light(bearing)))
        return out

    def _light(self, bearing: float) -> float:
        """The brightness of the latest image at `bearing` (1 without an image)."""
        try:
            cols = self.columns()
        except HardwareError:
            return 1.0
        x = (0.5 - bearing / self.fov) * len(cols)  # column 0 is the left edge, bearings grow to the left
        return float(cols[min(len(cols) - 1, max(0, int(x)))])
