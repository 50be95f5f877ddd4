"""The flight modes of a PX4 multirotor, as a client sees them.

This is the autopilot's behaviour without its wire format: arming, the
AUTO modes (takeoff, loiter, land, return), reposition, and offboard
setpoints, with PX4's rules where a client can notice them: a vehicle
armed on the ground disarms itself after ``DISARM_PREFLIGHT`` seconds
without a takeoff and ``DISARM_LANDED`` after landing; OFFBOARD is refused
unless a setpoint arrived within the last ``OFFBOARD_TIMEOUT`` seconds and
is left for HOLD when setpoints stop; a nearly flat battery lands the
vehicle. The MAVLink emulator and the in-process simulation both fly this
class, so a scenario behaves the same with or without the wire.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from bearcat.agents.uav.airframe import Airframe, Body, PointMass

DISARM_PREFLIGHT = 10.0  # s armed on the ground before auto-disarm (COM_DISARM_PRFLT)
DISARM_LANDED = 2.0  # s after touchdown (COM_DISARM_LAND)
OFFBOARD_TIMEOUT = 1.0  # s without a setpoint before offboard is lost (COM_OF_LOSS_T)
BATTERY_LAND = 0.05  # land at this charge (BAT_EMERGEN_THR)


class Main(IntEnum):
    """PX4 main modes (custom_mode bits 16-23)."""

    MANUAL = 1
    ALTCTL = 2
    POSCTL = 3
    AUTO = 4
    ACRO = 5
    OFFBOARD = 6
    STABILIZED = 7


class Sub(IntEnum):
    """PX4 AUTO sub-modes (custom_mode bits 24-31)."""

    NONE = 0
    READY = 1
    TAKEOFF = 2
    LOITER = 3
    MISSION = 4
    RTL = 5
    LAND = 6


class Landed(IntEnum):
    """MAV_LANDED_STATE."""

    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


class Result(IntEnum):
    """MAV_RESULT."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4


@dataclass
class Parameters:
    takeoff_alt: float = 2.5  # MIS_TAKEOFF_ALT, m above home
    rtl_alt: float = 30.0  # RTL_RETURN_ALT, m above home


class Flight:
    """One vehicle's flight state, advanced by ``step`` and commanded by the methods."""

    def __init__(self, airframe: Airframe, rng: np.random.Generator, start=(0.0, 0.0)) -> None:
        self.params = Parameters()
        self.mass = PointMass(airframe, Body.at_rest(*start), rng)
        self.home = np.array([start[0], start[1], 0.0])
        self.armed = False
        self.main, self.sub = Main.AUTO, Sub.LOITER
        self.target: np.ndarray | None = None
        self.setpoint: tuple[float, str, np.ndarray] | None = None  # (time, "velocity"|"position", vector)
        self._armed_at = 0.0
        self._touched_at: float | None = None
        self.note = ""  # the last thing the vehicle did on its own, for the log

    # ---------------------------------------------------------------- state

    @property
    def body(self) -> Body:
        return self.mass.body

    @property
    def landed(self) -> Landed:
        z, vz = self.body.position[2], self.body.velocity[2]
        if z <= 0.05 and abs(vz) < 0.05:
            return Landed.ON_GROUND
        if self.main == Main.AUTO and self.sub == Sub.TAKEOFF:
            return Landed.TAKEOFF
        if self.main == Main.AUTO and self.sub == Sub.LAND:
            return Landed.LANDING
        return Landed.IN_AIR

    @property
    def in_air(self) -> bool:
        return self.landed != Landed.ON_GROUND

    # ------------------------------------------------------------- commands

    def arm(self, now: float) -> Result:
        if self.body.battery <= BATTERY_LAND:
            return Result.DENIED
        if not self.armed:
            self.armed, self._armed_at = True, now
            self._touched_at = None
        return Result.ACCEPTED

    def disarm(self, force: bool = False) -> Result:
        if self.in_air and not force:
            return Result.DENIED
        self.armed = False
        self.target = None
        return Result.ACCEPTED

    def takeoff(self, altitude: float | None = None) -> Result:
        if not self.armed:
            return Result.DENIED
        z = self.params.takeoff_alt if altitude is None or not np.isfinite(altitude) else float(altitude)
        self.target = np.array([self.body.position[0], self.body.position[1], max(z, 1.0)])
        self.main, self.sub = Main.AUTO, Sub.TAKEOFF
        return Result.ACCEPTED

    def set_mode(self, main: int, sub: int, now: float) -> Result:
        try:
            main, sub = Main(main), Sub(sub)
        except ValueError:
            return Result.DENIED
        if main == Main.OFFBOARD:
            if self.setpoint is None or now - self.setpoint[0] > OFFBOARD_TIMEOUT:
                return Result.DENIED
            self.main, self.sub = main, Sub.NONE
            return Result.ACCEPTED
        if main != Main.AUTO:
            return Result.DENIED  # manual modes need a pilot on sticks
        if sub == Sub.LOITER:
            return self.hold()
        if sub == Sub.LAND:
            return self.land()
        if sub == Sub.RTL:
            return self.return_home()
        if sub == Sub.TAKEOFF:
            return self.takeoff()
        return Result.DENIED

    def hold(self) -> Result:
        self.main, self.sub = Main.AUTO, Sub.LOITER
        self.target = self.body.position.copy() if self.in_air else None
        return Result.ACCEPTED

    def reposition(self, east: float, north: float, up: float | None) -> Result:
        if not self.armed or not self.in_air:
            return Result.DENIED
        z = self.body.position[2] if up is None or not np.isfinite(up) else float(up)
        self.target = np.array([east, north, max(z, 1.0)])
        self.main, self.sub = Main.AUTO, Sub.LOITER
        return Result.ACCEPTED

    def land(self) -> Result:
        if not self.armed:
            return Result.DENIED
        self.main, self.sub = Main.AUTO, Sub.LAND
        self.target = np.array([self.body.position[0], self.body.position[1], 0.0])
        return Result.ACCEPTED

    def return_home(self) -> Result:
        if not self.armed or not self.in_air:
            return Result.DENIED
        self.main, self.sub = Main.AUTO, Sub.RTL
        self.target = None
        return Result.ACCEPTED

    def offboard(self, now: float, kind: str, vector) -> None:
        """An offboard setpoint: a velocity (east, north, up) or a position."""
        self.setpoint = (now, kind, np.asarray(vector, float))

    # ---------------------------------------------------------------- time

    def step(self, now: float, dt: float) -> None:
        if self.armed:
            self._autonomy(now)
        if not self.armed:
            self.mass.step(dt, motors=False)
            return
        if self.main == Main.OFFBOARD and self.setpoint is not None:
            _, kind, vector = self.setpoint
            if kind == "velocity":
                self.mass.step(dt, velocity=vector)
            else:
                self.mass.step(dt, target=vector)
        elif self.sub == Sub.RTL:
            self.mass.step(dt, target=self._rtl_leg())
        elif self.target is not None:
            self.mass.step(dt, target=self.target, landing=self.sub == Sub.LAND)
        else:
            self.mass.step(dt, velocity=np.zeros(3))

    def _autonomy(self, now: float) -> None:
        """What PX4 does without being asked."""
        if self.sub == Sub.TAKEOFF and self.target is not None and self.mass.at(self.target):
            self.main, self.sub = Main.AUTO, Sub.LOITER
        if self.main == Main.OFFBOARD and (self.setpoint is None or now - self.setpoint[0] > OFFBOARD_TIMEOUT):
            self.hold()
            self.note = "offboard setpoints stopped: holding"
        if self.in_air and self.body.battery <= BATTERY_LAND and self.sub != Sub.LAND:
            self.land()
            self.note = "battery empty: landing"
        if self.landed == Landed.ON_GROUND and self.sub not in (Sub.TAKEOFF,):
            if self.sub == Sub.LAND or self._touched_at is not None:
                self._touched_at = now if self._touched_at is None else self._touched_at
                if now - self._touched_at >= DISARM_LANDED:
                    self.disarm()
                    self.main, self.sub = Main.AUTO, Sub.LOITER
                    self._touched_at = None
            elif now - self._armed_at >= DISARM_PREFLIGHT:
                self.disarm()
                self.note = "armed without takeoff: disarmed"

    def _rtl_leg(self) -> np.ndarray:
        """RTL: climb to the return altitude, fly home at it, then land."""
        p = self.body.position
        cruise = max(self.params.rtl_alt, p[2])
        far = np.hypot(*(p[:2] - self.home[:2])) > 1.0
        if far and p[2] < cruise - 0.5 and self.target is None:
            return np.array([p[0], p[1], cruise])
        if far:
            self.target = np.array([self.home[0], self.home[1], max(cruise, p[2])])
            return self.target
        self.land()
        return self.target
