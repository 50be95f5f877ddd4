"""How the UAV agent flies a vehicle: one interface, two drivers.

The agent only asks for things (take off, go there, hold, return, land)
and reads the latest ``VehicleState``; it never waits for an answer, so it
stays a plain agent the runtimes tick. ``SimulatedAutopilot`` flies the
PX4 flight modes in-process on the agent's own clock (the simulation
runtime: virtual time, deterministic). ``MavsdkAutopilot`` is a MAVSDK
client on a MAVLink URL: the vehicle emulator, PX4 SITL or a real PX4,
with nothing else changed. Its commands run in order on a worker task of
the live runtime's event loop; a command the vehicle refuses is kept in
``failure`` for the agent to report.
"""

from __future__ import annotations

import asyncio
import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from bearcat.agents.uav.airframe import Airframe
from bearcat.agents.uav.flight import Flight, MainMode, SubMode
from bearcat.maps.geodesy import bearing, to_geodetic, to_local

if TYPE_CHECKING:
    from mavsdk.asyncio import Mavsdk

log = logging.getLogger("bearcat.uav")
TAKE_OFF_WAIT = 10.0  # s a reposition waits for a vehicle that was told to take off to leave the ground
CLOSE_WAIT = 3.0  # s to let go of a vehicle
RETRY_EVERY = 0.5  # s between tries of a command the vehicle refused
RETRY_FOR = 60.0  # s a refused command is tried again, unless a newer one replaces it


@dataclass(frozen=True)
class VehicleState:
    """The vehicle as last reported; ``alt`` is metres above home."""

    lat: float
    lon: float
    alt: float
    speed: float
    heading: float | None  # degrees clockwise from north, None when hovering
    armed: bool
    in_air: bool
    mode: str
    battery: float  # fraction left


class Autopilot(Protocol):
    failure: str | None

    def update(self, now: float) -> VehicleState | None: ...

    def take_off(self, altitude: float) -> None: ...

    def goto(self, lat: float, lon: float, altitude: float) -> None: ...

    def velocity(self, east: float, north: float, up: float) -> None: ...

    def hold(self) -> None: ...

    def return_home(self) -> None: ...

    def land(self) -> None: ...


MODE_NAMES = {
    (MainMode.AUTO, SubMode.READY): "ready",
    (MainMode.AUTO, SubMode.TAKEOFF): "takeoff",
    (MainMode.AUTO, SubMode.LOITER): "hold",
    (MainMode.AUTO, SubMode.MISSION): "mission",
    (MainMode.AUTO, SubMode.RTL): "return",
    (MainMode.AUTO, SubMode.LAND): "land",
}


class SimulatedAutopilot:
    """PX4's flight modes in-process, ``home`` = (lat, lon) of the take-off point."""

    def __init__(
        self, home: tuple[float, float], *, airframe: Airframe | None = None, rng: np.random.Generator
    ) -> None:
        self.home = (float(home[0]), float(home[1]))
        self.flight = Flight(airframe or Airframe(), rng)
        self.failure: str | None = None
        self._now: float | None = None

    def update(self, now: float) -> VehicleState:
        if self._now is not None and now > self._now:
            self.flight.step(now, now - self._now)
        self._now = now
        f = self.flight
        b = f.body
        lat, lon = to_geodetic(b.position[0], b.position[1], self.home)
        speed = float(np.hypot(*b.velocity[:2]))
        heading = bearing(b.velocity[0], b.velocity[1]) if speed > 0.2 else None
        mode = "offboard" if f.main == MainMode.OFFBOARD else MODE_NAMES.get((f.main, f.sub), "other")
        return VehicleState(lat, lon, float(b.position[2]), speed, heading, f.armed, f.in_air, mode, b.battery)

    def take_off(self, altitude: float) -> None:
        self._check("arm", self.flight.arm(self._now or 0.0))
        self.flight.params.takeoff_alt = float(altitude)
        self._check("take off", self.flight.takeoff())

    def goto(self, lat: float, lon: float, altitude: float) -> None:
        east, north = to_local(lat, lon, self.home)
        self._check("go to", self.flight.reposition(east, north, altitude))

    def velocity(self, east: float, north: float, up: float) -> None:
        now = self._now or 0.0
        self.flight.offboard(now, "velocity", (east, north, up))
        if self.flight.main != MainMode.OFFBOARD:
            self._check("offboard", self.flight.set_mode(MainMode.OFFBOARD, 0, now))

    def hold(self) -> None:
        self._check("hold", self.flight.hold())

    def return_home(self) -> None:
        self._check("return", self.flight.return_home())

    def land(self) -> None:
        self._check("land", self.flight.land())

    def _check(self, what: str, result) -> None:
        if result != 0:
            self.failure = f"{what} refused ({result.name.lower()})"


class MavsdkAutopilot:
    """A MAVSDK client of the vehicle at ``url`` (``udpin://0.0.0.0:14540`` for
    PX4 SITL and the emulator, ``serial:///dev/ttyACM0:57600`` for a real one)."""

    def __init__(self, url: str, *, sysid: int | None = None) -> None:
        self.url = url
        self.sysid = sysid
        self.failure: str | None = None
        self._state: dict = {}
        self._queue: asyncio.Queue | None = None
        self._tasks: list[asyncio.Task] = []
        self._mavsdk: Mavsdk | None = None
        self._offboard = False
        self._yaw = 0.0

    async def connect(self, timeout: float = 20.0) -> None:
        """Wait for the vehicle (raises TimeoutError naming the URL)."""
        from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
        from mavsdk.asyncio.plugins.action import ActionAsync
        from mavsdk.asyncio.plugins.offboard import OffboardAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        _route_mavsdk_logs()
        mavsdk = self._mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        await mavsdk.__aenter__()
        await mavsdk.add_any_connection(self.url)
        system = await self._system(mavsdk, timeout)
        if system is None:
            await self.close()
            raise TimeoutError(f"no vehicle answered on {self.url} within {timeout:g} s")
        self.action, self.telemetry, self.offboard = ActionAsync(system), TelemetryAsync(system), OffboardAsync(system)
        queue: asyncio.Queue = asyncio.Queue()
        self._queue = queue
        self._tasks = [asyncio.create_task(self._work(queue))] + [
            asyncio.create_task(self._follow(name))
            for name in ("position", "velocity_ned", "armed", "in_air", "flight_mode", "battery")
        ]

    async def _system(self, mavsdk: Mavsdk, timeout: float):
        if self.sysid is None:
            return await mavsdk.first_autopilot(timeout_s=timeout)
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        while loop.time() < deadline:
            for system in await mavsdk.get_systems():
                if await system.get_system_id() == self.sysid and await system.has_autopilot():
                    return system
            await asyncio.sleep(0.1)
        return None

    async def close(self, timeout: float = CLOSE_WAIT) -> None:
        """Let go of the vehicle, within ``timeout`` s: one that died does not answer."""
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._tasks = []
        if self._mavsdk is not None:
            mavsdk, self._mavsdk = self._mavsdk, None
            try:
                await asyncio.wait_for(asyncio.get_running_loop().run_in_executor(None, mavsdk.destroy), timeout)
            except TimeoutError:
                log.warning("%s: the vehicle's connection did not close within %g s; leaving it", self.url, timeout)

    def update(self, now: float) -> VehicleState | None:
        s = self._state
        if "position" not in s:
            return None
        p, v = s["position"], s.get("velocity_ned")
        speed = 0.0 if v is None else math.hypot(v.north_m_s, v.east_m_s)
        heading = None if v is None or speed <= 0.2 else bearing(v.east_m_s, v.north_m_s)
        battery = s.get("battery")
        mode = s.get("flight_mode")
        return VehicleState(
            p.latitude_deg,
            p.longitude_deg,
            p.relative_altitude_m,
            speed,
            heading,
            bool(s.get("armed", False)),
            bool(s.get("in_air", False)),
            "unknown" if mode is None else mode.name.lower().replace("_", "-"),
            1.0 if battery is None or battery.remaining_percent is None else battery.remaining_percent / 100.0,
        )

    def take_off(self, altitude: float) -> None:
        self._do("take off", self.action.set_takeoff_altitude, float(altitude))
        self._do("arm", self.action.arm)
        self._do("take off", self.action.takeoff)

    def goto(self, lat: float, lon: float, altitude: float) -> None:
        home = self._state.get("position")
        base = 0.0 if home is None else home.absolute_altitude_m - home.relative_altitude_m
        self._leave_offboard()
        self._do("go to", self._goto_when_flying, lat, lon, base + altitude)

    def velocity(self, east: float, north: float, up: float) -> None:
        """An offboard velocity setpoint; MAVSDK repeats the latest at 20 Hz,
        as PX4 needs, and the first one starts offboard mode."""
        from mavsdk.asyncio.plugins.offboard import VelocityNedYaw

        yaw = math.degrees(math.atan2(east, north)) if math.hypot(east, north) > 0.5 else self._yaw
        self._yaw = yaw
        self._do("offboard", self.offboard.set_velocity_ned, VelocityNedYaw(north, east, -up, yaw))
        if not self._offboard:
            self._offboard = True
            self._do("offboard", self.offboard.start)

    def hold(self) -> None:
        self._leave_offboard()
        self._do("hold", self.action.hold)

    def return_home(self) -> None:
        self._leave_offboard()
        self._do("return", self.action.return_to_launch)

    def land(self) -> None:
        self._leave_offboard()
        self._do("land", self.action.land)

    def _leave_offboard(self) -> None:
        """Stop MAVSDK's setpoint stream (the mode change that follows takes the vehicle out of offboard)."""
        if self._offboard:
            self._offboard = False
            self._do("offboard", self.offboard.stop)

    def _do(self, what: str, call, *args) -> None:
        if self._queue is not None:
            self._queue.put_nowait((what, call, args))

    async def _goto_when_flying(self, lat: float, lon: float, amsl: float) -> None:
        """PX4 takes a reposition only in the air, so one sent straight after
        the take-off waits (a while at most) until the vehicle says it is up."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + TAKE_OFF_WAIT
        while not self._state.get("in_air") and loop.time() < deadline:
            await asyncio.sleep(0.05)
        await self.action.goto_location(lat, lon, amsl, float("nan"))

    async def _work(self, queue: asyncio.Queue) -> None:
        """Send the commands in order. One the vehicle refuses (a reposition
        sent while it is still on the ground, a command lost on the link) is
        tried again until it holds, a newer command replaces it, or
        ``RETRY_FOR`` runs out: a refused goto must not leave the UAV
        hovering for the rest of the game."""
        loop = asyncio.get_running_loop()
        while True:
            what, call, args = await queue.get()
            give_up = loop.time() + RETRY_FOR
            while True:
                try:
                    await call(*args)
                    break
                except Exception as error:  # the vehicle refused or did not answer
                    if not queue.empty() or loop.time() > give_up or what == "offboard":
                        self.failure = f"{what} failed: {error}"
                        log.warning("%s: %s", self.url, self.failure)
                        break
                    log.info("%s: %s failed (%s); trying again", self.url, what, error)
                    await asyncio.sleep(RETRY_EVERY)

    async def _follow(self, name: str) -> None:
        async for value in getattr(self.telemetry, "subscribe_" + name)():
            self._state[name] = value


_routed = False


def _route_mavsdk_logs() -> None:
    """Send MAVSDK's own log lines to Python logging instead of stdout."""
    global _routed
    if _routed:
        return
    from mavsdk.logging import LogLevel, log_subscribe

    levels = {
        LogLevel.DEBUG: logging.DEBUG,
        LogLevel.INFO: logging.INFO,
        LogLevel.WARN: logging.WARNING,
        LogLevel.ERROR: logging.ERROR,
    }
    mavsdk_log = logging.getLogger("mavsdk")

    def forward(level, message, file, line):
        mavsdk_log.log(levels.get(level, logging.INFO), "%s", message)
        return True

    log_subscribe(forward)
    _routed = True
