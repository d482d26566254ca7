"""The `ros2` Drive: `cmd_vel` Twists out (clamped, rate-limited, a zero Twist on every stop and from a watchdog),
odometry (`odom`) and the battery (`battery_state`) in (docs/ros2.md)."""

from __future__ import annotations

import logging
import math
import threading

from components.ros2 import Ros2Driver
from drd.hosts import Device
from drd.hw.interfaces import HardwareError, StaleCommand
from drd.hw.ros2 import compose, yaw_of

log = logging.getLogger("drd.ros2")



#: How far outside 0..1 a `percentage` may stray and still be the charge (rounding): farther, it is on another scale.
PERCENTAGE_SLACK = 0.01


def charge(percentage: float, device: str) -> float:
    """The charge left, 0..1, from a BatteryState's `percentage`; HardwareError when the robot does not know it (NaN)
    or says it on another scale: a driver writing 30.0 for 30 % read as a full battery, so a battery floor never
    held (ros2 audit 18, #4). The ROS message's range is 0..1; a reading within PERCENTAGE_SLACK of it is clamped."""
    if not math.isfinite(percentage):
        raise HardwareError(f"{device}: the robot does not know its charge (percentage is NaN)")
    if not -PERCENTAGE_SLACK <= percentage <= 1 + PERCENTAGE_SLACK:
        raise HardwareError(f"{device}: battery percentage {percentage:g} is outside 0..1, the range of "
                            "sensor_msgs/BatteryState (a driver on a 0..100 scale?): the charge is not known")
    return min(1.0, max(0.0, percentage))

class Ros2Drive(Ros2Driver):
    """A ROS 2 mobile base. Options: `max_speed` (m/s, a manifest property); `driver_options`: see docs/ros2.md
    (`origin`, `watchdog`, `max_rate`, `max_age`, topics and frames)."""

    READINGS = frozenset({"odometry", "origin", "battery", "max_speed"})
    SETPOINTS = ("set_velocity", "stop")
    STOP = "stop"

    def __init__(self, device: Device, robot_id: str, backend: object = None) -> None:
        super().__init__(device, robot_id, backend)
        self.max_speed = self.option("max_speed", math.inf)
        opts = self.opts
        self._odom = self.subscribe("odom", opts.max_age, opts.frames.get("odom_frame"),
                                    child=opts.frames.get("base_frame"))
        self._battery = self.subscribe("battery", opts.status_max_age)
        self._cmd = self.publisher("cmd_vel")
        self._lock = threading.Lock()
        self._last_command = self.link.now()  # when drd last commanded (the watchdog's reference)
        self._last_sent = -math.inf  # when a Twist last went out (the rate limit's)
        self._pending: tuple[float, float] | None = None  # a command held back by the rate limit
        self._moving = False  # the last Twist sent (or held) is not zero: the watchdog has something to stop
        self._closed = False
        self.watchdog_stops = 0
        self.link.watch(self._check)

    # -- commands --------------------------------------------------------------------------------------------

    def set_velocity(self, v: float, omega: float, epoch: int | None = None) -> None:
        """`v` m/s (clamped to ±max_speed) and `omega` rad/s counter-clockwise."""
        self._fenced(epoch)
        if not (math.isfinite(v) and math.isfinite(omega)):
            self._send(0.0, 0.0)
            raise HardwareError(f"{self.describe()}: a velocity must be finite, got v={v}, omega={omega}")
        v = max(-self.max_speed, min(self.max_speed, v))
        if v == 0.0 and omega == 0.0:
            self._send(0.0, 0.0)
            return
        with self._lock:
            now = self.link.now()
            self._last_command = now
            self._moving = True
            if now - self._last_sent < 1.0 / self.opts.max_rate:
                self._pending = (v, omega)  # sent when the interval ends (`_check`), the latest one wins
                return
            self._pending = None
            self._put(v, omega, now)

    def stop(self, epoch: int | None = None) -> None:
        """A zero Twist, at once."""
        self._fenced(epoch)
        self._send(0.0, 0.0)

    def _fenced(self, epoch: int | None) -> None:
        """The fence; a command from a revoked grant stops the base before it is refused."""
        try:
            self.fence.check(epoch)
        except StaleCommand:
            self._send(0.0, 0.0)
            raise

    def _send(self, v: float, omega: float) -> None:
        """Send now, whatever the rate limit (a stop is never held back)."""
        with self._lock:
            now = self.link.now()
            self._last_command = now
            self._pending = None
            self._moving = v != 0.0 or omega != 0.0
            self._put(v, omega, now)

    def _put(self, v: float, omega: float, now: float) -> None:
        if self._closed:
            raise HardwareError(f"{self.describe()}: the driver is closed")
        self._last_sent = now
        self.publish(self._cmd, {"linear": {"x": v}, "angular": {"z": omega}})

    def _check(self) -> None:
        """The watchdog (on the link's thread, or each lockstep step): send a held command when its time comes, and a
        zero Twist once when drd has not commanded for `watchdog` seconds."""
        with self._lock:
            if self._closed:
                return
            now = self.link.now()
            if self._pending is not None and now - self._last_sent >= 1.0 / self.opts.max_rate:
                v, omega = self._pending
                self._pending = None
                self._put(v, omega, now)
            if self._moving and now - self._last_command >= self.opts.watchdog:
                self._pending, self._moving = None, False
                self.watchdog_stops += 1
                log.warning("%s: no command for %.2f s: zero Twist (watchdog)", self.describe(),
                            now - self._last_command)
                self._put(0.0, 0.0, now)

    def close(self) -> None:
        """A last zero Twist, then the driver's topics go."""
        with self._lock:
            if not self._closed:
                try:
                    self._put(0.0, 0.0, self.link.now())
                except Exception as e:  # the session may be gone first: nothing more to stop with
                    log.debug("%s: the closing zero Twist: %s", self.describe(), e)
                self._closed = True
        super().close()

    # -- readings --------------------------------------------------------------------------------------------

    def odometry(self) -> tuple[float, float, float]:
        """x, y (m) and heading (rad): the robot's odometry seen from the mission's map (`origin` ∘ odom)."""
        assert self._odom is not None
        pose = self._odom.get().pose.pose
        x, y, yaw = float(pose.position.x), float(pose.position.y), yaw_of(pose.orientation)
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)):
            raise HardwareError(f"{self.describe()}: the robot does not know where it is (odometry {x}, {y}, {yaw})")
        return compose(self.opts.origin, (x, y, yaw))

    def origin(self) -> tuple[float, float, float]:
        """Where the odometry began, in the mission's map: the `origin` option."""
        return self.opts.origin

    def battery(self) -> float:
        """The charge left, 0..1: `battery_state`'s `percentage`."""
        if self._battery is None:
            raise HardwareError(f"{self.describe()}: no battery topic (topics: {{battery: false}})")
        return charge(float(self._battery.get().percentage), self.describe())
