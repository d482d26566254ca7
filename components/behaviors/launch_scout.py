"""LaunchScout: throw the next Scout of the magazine straight ahead, through the door the Ranger faces.

The Scout is the `scout` resource the runtime bound (it fails when that one is not in the magazine: the
launcher throws only a Scout its behavior holds); without a binding (a test rig), the first of `loaded()`.
The distance is `min(max_range, launcher.max_range, front - CLEARANCE)` where `front` is the front range beam
(the room's far wall seen through the doorway): the Scout lands well inside the room, short of its back wall.
The Scout's property naming its carrier (`carrier_property`, `carrier` by default) is cleared in the Static
Dependency Database, so a `where` on it sees the Scout no longer aboard.
Without a range sensor (the manifest gives this component the launcher only), the distance is the cap alone.
"""

from __future__ import annotations

from components.behaviors.scan import front_range
from drd.runtime.component import Component, Status

#: How far short of what the front beam sees (m) the Scout should land.
CLEARANCE = 1.0
#: Shortest throw worth making (m): anything less means a wall or closed door straight ahead.
MIN_THROW = 1.5
#: The front beam: the beams within this angle (rad) of the heading, half a beam step of margin included.
FRONT = 0.03


class LaunchScout(Component):
    def step(self, now: float) -> Status:
        launcher = self.device("launcher")
        loaded = tuple(launcher.loaded())
        if not loaded:
            self.ctx.log("LaunchScout: the magazine is empty")
            return Status.FAILURE
        bound = self.ctx.resources.get("scout")
        if bound is not None and bound not in loaded:  # the launcher throws only the Scout this behavior holds
            self.ctx.log(f"LaunchScout: {bound}, the robot it holds, is not in its launcher's magazine"
                         f" ({', '.join(loaded)})")
            return Status.FAILURE
        scout = bound if bound is not None else loaded[0]  # unbound: a test rig without resources
        distance = min(float(self.ctx.params["max_range"]), float(launcher.max_range))
        front: float | None = None
        if "ranges" in self.ctx.devices:
            scan = self.device("ranges").scan()
            front = front_range(scan, FRONT)
            distance = min(distance, front - CLEARANCE)
        if distance < MIN_THROW:
            # what stands in the way, in the user's words (worlds audit 17, D9: "target out of range (0.79 m)"
            # said nothing of the door closed in front of the launcher)
            blocked = front is not None and front - CLEARANCE < MIN_THROW
            self.ctx.log(f"LaunchScout: something {front:.2f} m ahead (a closed or blocked door, a wall): no room"
                         f" for a throw of at least {MIN_THROW:g} m" if blocked and front is not None else
                         f"LaunchScout: target out of range ({distance:.2f} m; at least {MIN_THROW:g} m)")
            return Status.FAILURE
        aboard = str(self.ctx.params["carrier_property"])  # read before the throw: a throw is not undone
        landing = launcher.launch(scout, 0.0, distance)
        self.ctx.outputs["scout"] = scout
        try:  # it left the magazine: the Static Dependency Database must say so
            self.update_dependency(str(scout), aboard, "")
        except LookupError:
            pass  # run outside an executive (a test rig): nobody keeps the database
        self.ctx.outputs["landing"] = (landing.x, landing.y)
        self.ctx.emit("ScoutLaunched", scout=scout, distance=round(distance, 3))
        return Status.SUCCESS
