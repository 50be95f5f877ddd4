"""A PX4 quadrotor's MAVLink face, without the socket.

``Px4Face`` turns incoming pymavlink messages into ``Flight`` commands and
the flight state into the telemetry streams a PX4 sends, at PX4's default
rates, so an unmodified MAVSDK client takes its PX4 code paths: heartbeat
as a PX4 quadrotor with base and custom mode (armed state and flight mode
come only from there), GLOBAL_POSITION_INT, EXTENDED_SYS_STATE (in-air
and landed state), SYS_STATUS with the health bits, BATTERY_STATUS,
HOME_POSITION, GPS_RAW_INT and ATTITUDE; AUTOPILOT_VERSION and
HOME_POSITION on request; the parameter protocol for MIS_TAKEOFF_ALT and
RTL_RETURN_ALT; acknowledgements for arm/disarm, takeoff, set mode,
reposition, land and return; and UNSUPPORTED for any other command, so a
client fails at once instead of after its 2 s of retries.

Local metres are (east, north, up) from home; MAVLink's local frame is
NED, and its altitudes are AMSL in millimetres.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mav

from bearcat.agents.uav.flight import CommandResult, Flight, MainMode
from bearcat.maps.geodesy import bearing, to_geodetic, to_local

# Telemetry streams and their periods (s), PX4's defaults on a telemetry link.
STREAMS = {
    "heartbeat": 0.25,
    "global_position_int": 0.1,
    "attitude": 0.1,
    "extended_sys_state": 0.5,
    "sys_status": 1.0,
    "battery_status": 1.0,
    "gps_raw_int": 0.2,
    "home_position": 2.0,
}
PX4_VERSION = (1 << 24) | (15 << 16) | (0 << 8) | 255  # 1.15.0 release
HEALTH = (
    mav.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mav.MAV_SYS_STATUS_SENSOR_3D_MAG
    | mav.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mav.MAV_SYS_STATUS_SENSOR_GPS
    | mav.MAV_SYS_STATUS_SENSOR_RC_RECEIVER
    | mav.MAV_SYS_STATUS_PREARM_CHECK
)
PARAMS = {"MIS_TAKEOFF_ALT": "takeoff_alt", "RTL_RETURN_ALT": "rtl_alt"}
FORCE = 21196  # ARM_DISARM param2 that forces a disarm in flight


class Px4Face:
    """The vehicle ``sysid`` (component 1) whose home is ``home`` = (lat, lon, alt AMSL)."""

    def __init__(self, flight: Flight, sysid: int, home: tuple[float, float, float]) -> None:
        self.flight = flight
        self.sysid = sysid
        self.home = home
        self._due = dict.fromkeys(STREAMS, 0.0)
        self._boot: float | None = None

    # -------------------------------------------------------------- inbound

    def handle(self, msg, now: float) -> list:
        """The replies to one received message (commands are acknowledged to their sender)."""
        kind = msg.get_type()
        if kind in ("COMMAND_LONG", "COMMAND_INT"):
            if msg.target_system not in (0, self.sysid):
                return []
            return self._command(msg, now)
        if kind == "PARAM_REQUEST_READ" and msg.target_system in (0, self.sysid):
            name = msg.param_id if msg.param_index < 0 else _param_name(msg.param_index)
            return [] if name not in PARAMS else [self._param(name)]
        if kind == "PARAM_REQUEST_LIST" and msg.target_system in (0, self.sysid):
            return [self._param(name) for name in PARAMS]
        if kind == "PARAM_SET" and msg.target_system in (0, self.sysid) and msg.param_id in PARAMS:
            setattr(self.flight.params, PARAMS[msg.param_id], float(msg.param_value))
            return [self._param(msg.param_id)]
        if kind == "SET_POSITION_TARGET_LOCAL_NED" and msg.target_system in (0, self.sysid):
            self._offboard_local(msg, now)
        elif kind == "SET_POSITION_TARGET_GLOBAL_INT" and msg.target_system in (0, self.sysid):
            east, north = self._local(msg.lat_int / 1e7, msg.lon_int / 1e7)
            self.flight.offboard(now, "position", (east, north, msg.alt - self.home[2]))
        return []

    def _command(self, msg, now: float) -> list:
        c, f = msg.command, self.flight
        p = [msg.param1, msg.param2, msg.param3, msg.param4]
        extra = []
        if c == mav.MAV_CMD_COMPONENT_ARM_DISARM:
            result = f.arm(now) if p[0] >= 0.5 else f.disarm(force=int(p[1]) == FORCE)
        elif c == mav.MAV_CMD_NAV_TAKEOFF:
            alt = _param7(msg)
            result = f.takeoff(None if math.isnan(alt) else alt - self.home[2])
        elif c == mav.MAV_CMD_DO_SET_MODE:
            result = f.set_mode(int(p[1]), int(p[2]), now)
        elif c == mav.MAV_CMD_DO_REPOSITION:
            lat, lon, alt = _position(msg)
            if math.isnan(lat) or math.isnan(lon):
                east, north = f.body.position[0], f.body.position[1]
            else:
                east, north = self._local(lat, lon)
            result = f.reposition(east, north, None if math.isnan(alt) else alt - self.home[2])
        elif c == mav.MAV_CMD_NAV_LAND:
            result = f.land()
        elif c == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            result = f.return_home()
        elif c in (mav.MAV_CMD_REQUEST_MESSAGE, mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            wanted = int(p[0]) if c == mav.MAV_CMD_REQUEST_MESSAGE else mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION
            reply = {
                mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION: self._version,
                mav.MAVLINK_MSG_ID_HOME_POSITION: self._home_position,
            }.get(wanted)
            result = CommandResult.UNSUPPORTED if reply is None else CommandResult.ACCEPTED
            extra = [] if reply is None else [reply(now)]
        elif c == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = CommandResult.ACCEPTED  # the streams keep PX4's default rates
        else:
            result = CommandResult.UNSUPPORTED
        ack = mav.MAVLink_command_ack_message(
            c, int(result), 0, 0, target_system=msg.get_srcSystem(), target_component=msg.get_srcComponent()
        )
        return [ack, *extra]

    def _offboard_local(self, msg, now: float) -> None:
        ignore_position = msg.type_mask & 0b111 == 0b111
        if ignore_position:
            self.flight.offboard(now, "velocity", (msg.vy, msg.vx, -msg.vz))
        else:
            self.flight.offboard(now, "position", (msg.y, msg.x, -msg.z))

    # ------------------------------------------------------------- outbound

    def telemetry(self, now: float) -> list:
        """The stream messages due at ``now``."""
        if self._boot is None:
            self._boot = now
        out = []
        for name, period in STREAMS.items():
            if now >= self._due[name]:
                self._due[name] = max(self._due[name] + period, now)
                out.append(getattr(self, "_" + name)(now))
        return out

    def _heartbeat(self, now: float):
        f = self.flight
        base = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mav.MAV_MODE_FLAG_SAFETY_ARMED if f.armed else 0)
        custom = (int(f.main) << 16) | (int(f.sub) << 24 if f.main == MainMode.AUTO else 0)
        status = mav.MAV_STATE_ACTIVE if f.armed else mav.MAV_STATE_STANDBY
        return mav.MAVLink_heartbeat_message(mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_PX4, base, custom, status, 3)

    def _global_position_int(self, now: float):
        b = self.flight.body
        lat, lon = self._geodetic(b.position[0], b.position[1])
        ve, vn, vu = b.velocity
        heading = bearing(ve, vn) if math.hypot(ve, vn) > 0.2 else 0.0
        return mav.MAVLink_global_position_int_message(
            self._ms(now),
            round(lat * 1e7),
            round(lon * 1e7),
            round((self.home[2] + b.position[2]) * 1000),
            round(b.position[2] * 1000),
            round(vn * 100),
            round(ve * 100),
            round(-vu * 100),
            round(heading * 100),
        )

    def _attitude(self, now: float):
        b = self.flight.body
        yaw = math.atan2(b.velocity[0], b.velocity[1]) if math.hypot(*b.velocity[:2]) > 0.2 else 0.0
        return mav.MAVLink_attitude_message(self._ms(now), 0.0, 0.0, yaw, 0.0, 0.0, 0.0)

    def _extended_sys_state(self, now: float):
        return mav.MAVLink_extended_sys_state_message(mav.MAV_VTOL_STATE_UNDEFINED, int(self.flight.landed))

    def _sys_status(self, now: float):
        volts, remaining = self._battery()
        return mav.MAVLink_sys_status_message(HEALTH, HEALTH, HEALTH, 200, volts, 1000, remaining, 0, 0, 0, 0, 0, 0)

    def _battery_status(self, now: float):
        volts, remaining = self._battery()
        cells = [volts // 4] * 4 + [65535] * 6
        return mav.MAVLink_battery_status_message(
            0, mav.MAV_BATTERY_FUNCTION_ALL, mav.MAV_BATTERY_TYPE_LIPO, 2500, cells, 1000, -1, -1, remaining
        )

    def _gps_raw_int(self, now: float):
        b = self.flight.body
        lat, lon = self._geodetic(b.position[0], b.position[1])
        speed = math.hypot(b.velocity[0], b.velocity[1])
        return mav.MAVLink_gps_raw_int_message(
            int(now * 1e6),
            mav.GPS_FIX_TYPE_3D_FIX,
            round(lat * 1e7),
            round(lon * 1e7),
            round((self.home[2] + b.position[2]) * 1000),
            80,
            120,
            round(speed * 100),
            65535,
            14,
        )

    def _home_position(self, now: float):
        lat, lon, alt = self.home
        return mav.MAVLink_home_position_message(
            round(lat * 1e7), round(lon * 1e7), round(alt * 1000), 0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0
        )

    def _version(self, now: float):
        capabilities = (
            mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2
            | mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            | mav.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
            | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
            | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
        )
        return mav.MAVLink_autopilot_version_message(
            capabilities, PX4_VERSION, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 1000 + self.sysid
        )

    def _param(self, name: str):
        names = list(PARAMS)
        value = getattr(self.flight.params, PARAMS[name])
        return mav.MAVLink_param_value_message(
            name.encode(), value, mav.MAV_PARAM_TYPE_REAL32, len(names), names.index(name)
        )

    # -------------------------------------------------------------- helpers

    def _battery(self) -> tuple[int, int]:
        charge = self.flight.body.battery
        return round((14.0 + 2.8 * charge) * 1000), round(100 * charge)

    def _ms(self, now: float) -> int:
        return int((now - (self._boot or now)) * 1000) & 0xFFFFFFFF

    def _geodetic(self, east: float, north: float) -> tuple[float, float]:
        return to_geodetic(east, north, self.home[:2])

    def _local(self, lat: float, lon: float) -> tuple[float, float]:
        return to_local(lat, lon, self.home[:2])


def _param_name(index: int) -> str | None:
    names = list(PARAMS)
    return names[index] if 0 <= index < len(names) else None


def _param7(msg) -> float:
    return float(msg.param7) if msg.get_type() == "COMMAND_LONG" else float(msg.z)


def _position(msg) -> tuple[float, float, float]:
    """Latitude, longitude (degrees) and AMSL altitude of a reposition command."""
    if msg.get_type() == "COMMAND_INT":
        return msg.x / 1e7, msg.y / 1e7, float(msg.z)
    return float(msg.param5), float(msg.param6), float(msg.param7)
