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


class MainMode(IntEnum):
    """PX4's custom main mode (bits 16-23 of HEARTBEAT's custom_mode)."""

    MANUAL = 1
    ALTCTL = 2
    POSCTL = 3
    AUTO = 4
    ACRO = 5
    OFFBOARD = 6
    STABILIZED = 7


class SubMode(IntEnum):
    """PX4's AUTO sub mode (bits 24-31 of custom_mode)."""

    NONE = 0
    READY = 1
    TAKEOFF = 2
    LOITER = 3
    MISSION = 4
    RTL = 5
    LAND = 6


class LandedState(IntEnum):
    """Whether the vehicle is on the ground, in the air or between (MAV_LANDED_STATE)."""

    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


class CommandResult(IntEnum):
    """What the vehicle answers a command with (MAV_RESULT)."""

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
        self.main, self.sub = MainMode.AUTO, SubMode.LOITER
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
    def landed(self) -> LandedState:
        z, vz = self.body.position[2], self.body.velocity[2]
        if z <= 0.05 and abs(vz) < 0.05:
            return LandedState.ON_GROUND
        if self.main == MainMode.AUTO and self.sub == SubMode.TAKEOFF:
            return LandedState.TAKEOFF
        if self.main == MainMode.AUTO and self.sub == SubMode.LAND:
            return LandedState.LANDING
        return LandedState.IN_AIR

    @property
    def in_air(self) -> bool:
        return self.landed != LandedState.ON_GROUND

    # ------------------------------------------------------------- commands

    def arm(self, now: float) -> CommandResult:
        if self.body.battery <= BATTERY_LAND:
            return CommandResult.DENIED
        if not self.armed:
            self.armed, self._armed_at = True, now
            self._touched_at = None
        return CommandResult.ACCEPTED

    def disarm(self, force: bool = False) -> CommandResult:
        if self.in_air and not force:
            return CommandResult.DENIED
        self.armed = False
        self.target = None
        return CommandResult.ACCEPTED

    def takeoff(self, altitude: float | None = None) -> CommandResult:
        if not self.armed:
            return CommandResult.DENIED
        z = self.params.takeoff_alt if altitude is None or not np.isfinite(altitude) else float(altitude)
        self.target = np.array([self.body.position[0], self.body.position[1], max(z, 1.0)])
        self.main, self.sub = MainMode.AUTO, SubMode.TAKEOFF
        return CommandResult.ACCEPTED

    def set_mode(self, main: int, sub: int, now: float) -> CommandResult:
        try:
            main, sub = MainMode(main), SubMode(sub)
        except ValueError:
            return CommandResult.DENIED
        if main == MainMode.OFFBOARD:
            if self.setpoint is None or now - self.setpoint[0] > OFFBOARD_TIMEOUT:
                return CommandResult.DENIED
            self.main, self.sub = main, SubMode.NONE
            return CommandResult.ACCEPTED
        if main != MainMode.AUTO:
            return CommandResult.DENIED  # manual modes need a pilot on sticks
        if sub == SubMode.LOITER:
            return self.hold()
        if sub == SubMode.LAND:
            return self.land()
        if sub == SubMode.RTL:
            return self.return_home()
        if sub == SubMode.TAKEOFF:
            return self.takeoff()
        return CommandResult.DENIED

    def hold(self) -> CommandResult:
        self.main, self.sub = MainMode.AUTO, SubMode.LOITER
        self.target = self.body.position.copy() if self.in_air else None
        return CommandResult.ACCEPTED

    def reposition(self, east: float, north: float, up: float | None) -> CommandResult:
        if not self.armed or not self.in_air:
            return CommandResult.DENIED
        z = self.body.position[2] if up is None or not np.isfinite(up) else float(up)
        self.target = np.array([east, north, max(z, 1.0)])
        self.main, self.sub = MainMode.AUTO, SubMode.LOITER
        return CommandResult.ACCEPTED

    def land(self) -> CommandResult:
        if not self.armed:
            return CommandResult.DENIED
        self.main, self.sub = MainMode.AUTO, SubMode.LAND
        self.target = np.array([self.body.position[0], self.body.position[1], 0.0])
        return CommandResult.ACCEPTED

    def return_home(self) -> CommandResult:
        if not self.armed or not self.in_air:
            return CommandResult.DENIED
        self.main, self.sub = MainMode.AUTO, SubMode.RTL
        self.target = None
        return CommandResult.ACCEPTED

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
        if self.main == MainMode.OFFBOARD and self.setpoint is not None:
            _, kind, vector = self.setpoint
            if kind == "velocity":
                self.mass.step(dt, velocity=vector)
            else:
                self.mass.step(dt, target=vector)
        elif self.sub == SubMode.RTL:
            self.mass.step(dt, target=self._rtl_leg())
        elif self.target is not None:
            self.mass.step(dt, target=self.target, landing=self.sub == SubMode.LAND)
        else:
            self.mass.step(dt, velocity=np.zeros(3))

    def _autonomy(self, now: float) -> None:
        """What PX4 does without being asked."""
        if self.sub == SubMode.TAKEOFF and self.target is not None and self.mass.at(self.target):
            self.main, self.sub = MainMode.AUTO, SubMode.LOITER
        if self.main == MainMode.OFFBOARD and (self.setpoint is None or now - self.setpoint[0] > OFFBOARD_TIMEOUT):
            self.hold()
            self.note = "offboard setpoints stopped: holding"
        if self.in_air and self.body.battery <= BATTERY_LAND and self.sub != SubMode.LAND:
            self.land()
            self.note = "battery empty: landing"
        if self.landed == LandedState.ON_GROUND and self.sub not in (SubMode.TAKEOFF,):
            if self.sub == SubMode.LAND or self._touched_at is not None:
                self._touched_at = now if self._touched_at is None else self._touched_at
                if now - self._touched_at >= DISARM_LANDED:
                    self.disarm()
                    self.main, self.sub = MainMode.AUTO, SubMode.LOITER
                    self._touched_at = None
            elif now - self._armed_at >= DISARM_PREFLIGHT:
                self.disarm()
                self.note = "armed without takeoff: disarmed"

    def _rtl_leg(self) -> np.ndarray | None:
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
