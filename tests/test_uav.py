"""The UAV: the airframe's physics, PX4's flight rules, and the MAVSDK client
flying the MAVLink vehicle emulator over real UDP on loopback (each
emulator its own ``bearcat vehicle`` process)."""

from __future__ import annotations

import asyncio
import math
import os
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil

from bearcat.agents.uav.agent import UavAgent
from bearcat.agents.uav.airframe import Airframe, Body, PointMass
from bearcat.agents.uav.autopilot import MavsdkAutopilot, SimulatedAutopilot
from bearcat.agents.uav.flight import DISARM_LANDED, DISARM_PREFLIGHT, CommandResult, Flight, MainMode, SubMode
from bearcat.bus import keys
from bearcat.bus.messages import Control, Truth, UavTask
from bearcat.maps.geodesy import to_geodetic, to_local

HOME = (37.8719, -122.2585, 60.0)
GAME = "sky"

# ---------------------------------------------------------------------- physics


def test_point_mass_respects_its_limits_and_arrives_without_overshoot():
    f = Airframe(max_speed=8.0, max_accel=3.0, max_climb=3.0, max_descent=1.5)
    mass = PointMass(f, Body.at_rest(), np.random.default_rng(0))
    target = np.array([60.0, 20.0, 10.0])
    dt, previous, closest_after = 0.02, np.zeros(3), []
    for _ in range(int(40 / dt)):
        mass.step(dt, target=target)
        v = mass.body.velocity
        assert np.hypot(*v[:2]) <= f.max_speed + 1e-9
        assert -f.max_descent - 1e-9 <= v[2] <= f.max_climb + 1e-9
        # The horizontal acceleration is the controller's, bounded (no wind here).
        assert np.hypot(*(v[:2] - previous[:2])) / dt <= f.max_accel + 1e-6
        previous = v.copy()
        closest_after.append(np.dot(target[:2] - mass.body.position[:2], target[:2]) / np.linalg.norm(target[:2]))
    assert mass.at(target)
    assert min(closest_after) > -0.5  # never more than half a metre past the target along the leg


def test_holding_against_wind_costs_battery_and_gusts_leave_a_metre_or_two():
    left = []
    for wind in ((0.0, 0.0), (5.0, -3.0)):
        mass = PointMass(Airframe(wind=wind), Body(np.array([0.0, 0.0, 10.0]), np.zeros(3)), np.random.default_rng(1))
        for _ in range(3000):
            mass.step(0.02, target=(0.0, 0.0, 10.0))
        assert np.hypot(*mass.body.position[:2]) < 0.3
        left.append(mass.body.battery)
    assert left[1] < left[0]
    gusty = Airframe(gust=2.0)
    mass = PointMass(gusty, Body(np.array([0.0, 0.0, 10.0]), np.zeros(3)), np.random.default_rng(2))
    errors = []
    for _k in range(20000):
        mass.step(0.02, target=(0.0, 0.0, 10.0))
        errors.append(np.hypot(*mass.body.position[:2]))
    assert 0.2 < np.sqrt(np.mean(np.square(errors))) < 2.5  # the thesis: hover accuracy of 1-2 m


def test_battery_drains_with_hover_time():
    f = Airframe(endurance=100.0, speed_drain=0.0)
    mass = PointMass(f, Body(np.array([0.0, 0.0, 5.0]), np.zeros(3)), np.random.default_rng(0))
    for _ in range(250):
        mass.step(0.1, target=(0.0, 0.0, 5.0))
    assert mass.body.battery == pytest.approx(0.75, abs=1e-9)


# ---------------------------------------------------------------------- PX4's rules


def _flight() -> Flight:
    return Flight(Airframe(), np.random.default_rng(0))


def _run(flight: Flight, t0: float, seconds: float, dt: float = 0.05) -> float:
    t = t0
    for _ in range(round(seconds / dt)):
        t += dt
        flight.step(t, dt)
    return t


def test_takeoff_hold_then_land_disarms_after_touchdown():
    f = _flight()
    assert f.takeoff() == CommandResult.DENIED  # not armed
    assert f.arm(0.0) == CommandResult.ACCEPTED and f.takeoff(6.0) == CommandResult.ACCEPTED
    t = _run(f, 0.0, 6.0)
    assert (f.main, f.sub) == (MainMode.AUTO, SubMode.LOITER) and abs(f.body.position[2] - 6.0) < 0.5
    assert f.disarm() == CommandResult.DENIED  # in the air
    assert f.land() == CommandResult.ACCEPTED
    t = _run(f, t, 6.0 / 1.5 + 1.0)
    assert not f.in_air and f.armed
    _run(f, t, DISARM_LANDED + 0.2)
    assert not f.armed


def test_armed_on_the_ground_disarms_itself_and_offboard_needs_setpoints():
    f = _flight()
    f.arm(0.0)
    assert f.set_mode(MainMode.OFFBOARD, 0, 0.5) == CommandResult.DENIED
    _run(f, 0.0, DISARM_PREFLIGHT + 0.2)
    assert not f.armed
    f.arm(20.0)
    f.takeoff(5.0)
    t = _run(f, 20.0, 5.0)
    f.offboard(t, "velocity", (2.0, 0.0, 0.0))
    assert f.set_mode(MainMode.OFFBOARD, 0, t) == CommandResult.ACCEPTED
    for _ in range(40):  # setpoints streamed at 10 Hz for 4 s
        t = _run(f, t, 0.1)
        f.offboard(t, "velocity", (2.0, 0.0, 0.0))
    assert f.body.velocity[0] == pytest.approx(2.0, abs=0.1)
    _run(f, t, 1.5)  # the stream stops: PX4 falls back to hold
    assert (f.main, f.sub) == (MainMode.AUTO, SubMode.LOITER)


def test_return_climbs_flies_home_and_lands():
    f = _flight()
    f.params.rtl_alt = 12.0
    f.arm(0.0)
    f.takeoff(5.0)
    t = _run(f, 0.0, 4.0)
    f.reposition(40.0, -30.0, 5.0)
    t = _run(f, t, 15.0)
    assert np.hypot(f.body.position[0] - 40, f.body.position[1] + 30) < 1.0
    assert f.return_home() == CommandResult.ACCEPTED
    peak = 0.0
    for _ in range(60):
        t = _run(f, t, 0.5)
        peak = max(peak, f.body.position[2])
    assert peak >= 11.5 and np.hypot(*f.body.position[:2]) < 1.0 and not f.armed


# The emulator's physics rate and the simulation's tick: the flight model must not overshoot at either.
STEPS = pytest.mark.parametrize("dt", [0.02, 0.1])
OVERSHOOT = 0.05  # m: 2 % of the lowest take-off altitude, and well inside any GPS's or barometer's noise


def _quickest(distance: float, top_speed: float, accel: float) -> float:
    """The shortest time to cover ``distance`` from rest to rest within a speed and an acceleration limit."""
    if distance <= top_speed**2 / accel:
        return 2.0 * math.sqrt(distance / accel)
    return distance / top_speed + top_speed / accel


def _approach(flight: Flight, t: float, seconds: float, dt: float, axis: int, goal: float) -> tuple[float, float]:
    """Fly for ``seconds``: the highest coordinate on ``axis`` reached, and the time from ``t`` after which the
    vehicle stayed within 5 cm of ``goal`` for good."""
    peak, settled = -math.inf, None
    for k in range(1, round(seconds / dt) + 1):
        flight.step(t + k * dt, dt)
        x = float(flight.body.position[axis])
        peak = max(peak, x)
        if abs(x - goal) > 0.05:
            settled = None
        elif settled is None:
            settled = k * dt
    assert settled is not None, f"never settled at {goal}"
    return peak, settled


@STEPS
@pytest.mark.parametrize("altitude", [2.5, 5.0, 10.0])
def test_takeoff_stops_at_its_altitude_without_overshoot(altitude, dt):
    f = _flight()
    f.arm(0.0)
    f.takeoff(altitude)
    peak, settled = _approach(f, 0.0, 20.0, dt, axis=2, goal=altitude)
    a = f.mass.airframe
    assert peak <= altitude + OVERSHOOT
    # No sluggish cure: there within five response times of the quickest climb the limits allow.
    assert settled <= _quickest(altitude, a.max_climb, a.max_accel) + 5 * a.response
    assert (f.main, f.sub) == (MainMode.AUTO, SubMode.LOITER)


@STEPS
def test_reposition_stops_at_its_target_without_overshoot(dt):
    f = _flight()
    f.arm(0.0)
    f.takeoff(10.0)
    t = _run(f, 0.0, 10.0, dt)
    start = f.body.position.copy()
    f.reposition(start[0] + 20.0, start[1], 10.0)
    peak, settled = _approach(f, t, 20.0, dt, axis=0, goal=start[0] + 20.0)
    a = f.mass.airframe
    assert peak <= start[0] + 20.0 + OVERSHOOT
    assert settled <= _quickest(20.0, a.max_speed, a.max_accel) + 5 * a.response
    assert abs(f.body.position[1] - start[1]) < 0.05 and abs(f.body.position[2] - 10.0) < 0.05


# ---------------------------------------------------------------------- over UDP


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Vehicle:
    """A ``bearcat vehicle`` process sending to a free UDP port on loopback."""

    def __init__(self, sysid: int = 1, home=HOME) -> None:
        self.port = _free_udp_port()
        self.sysid = sysid
        home_arg = ",".join(str(v) for v in home)
        self.process = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "bearcat",
                "vehicle",
                "--connect",
                f"udpout:127.0.0.1:{self.port}",
                "--sysid",
                str(sysid),
                "--home",
                home_arg,
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )

    @property
    def url(self) -> str:
        return f"udpin://0.0.0.0:{self.port}"

    def stop(self) -> str:
        self.process.terminate()
        out, err = self.process.communicate(timeout=10)
        assert self.process.returncode == 0, err
        return out


@pytest.fixture
def vehicle():
    v = Vehicle()
    yield v
    if v.process.poll() is None:
        v.stop()


def _agent(autopilot, **options) -> UavAgent:
    return UavAgent(GAME, "q1", autopilot, altitude=5.0, camera_radius=10.0, watch=("defender",), **options)


async def _fly(agent: UavAgent, seconds: float, until=None, feed=()) -> float:
    """Tick ``agent`` at its rate on the wall clock for up to ``seconds``;
    ``feed`` is a callable giving messages to hand it each tick."""
    loop = asyncio.get_running_loop()
    end = loop.time() + seconds
    while loop.time() < end:
        now = time.monotonic()
        for key, message in feed(now) if feed else ():
            agent.handle(key, message, now)
        agent.tick(now)
        if until is not None and agent.state is not None and until(agent.state):
            return loop.time()
        await asyncio.sleep(agent.period)
    raise AssertionError(f"not done within {seconds} s; state {agent.state}, events {agent.events}")


def _start(agent: UavAgent) -> None:
    now = time.monotonic()
    agent.start(now)
    agent.handle(keys.control(GAME), Control(t=now, command="start"), now)


def _task(seq: int, east: float, north: float, kind: str = "search") -> UavTask:
    lat, lon = to_geodetic(east, north, HOME[:2])
    return UavTask(uav="q1", seq=seq, t=time.monotonic(), kind=kind, lat=lat, lon=lon, alt=5.0)


def test_mavsdk_client_arms_takes_off_flies_a_goto_and_lands(vehicle):
    async def scenario():
        autopilot = MavsdkAutopilot(vehicle.url)
        await autopilot.connect(timeout=10.0)
        try:
            agent = _agent(autopilot, link_timeout=60.0)
            _start(agent)
            await _fly(agent, 15.0, until=lambda s: s.in_air and s.alt > 4.5 and s.mode == "hold")
            agent.handle(keys.uav_task(GAME, "q1"), _task(1, 30.0, 20.0), time.monotonic())
            await _fly(
                agent, 20.0, until=lambda s: math.hypot(*to_local(s.lat, s.lon, HOME[:2])) > 35.5 and s.speed < 0.3
            )
            east, north = to_local(agent.state.lat, agent.state.lon, HOME[:2])
            assert math.hypot(east - 30.0, north - 20.0) < 1.0
            assert agent.state.armed and abs(agent.state.alt - 5.0) < 0.6
            agent.handle(keys.uav_task(GAME, "q1"), _task(2, 0.0, 0.0, kind="land"), time.monotonic())
            await _fly(agent, 20.0, until=lambda s: not s.armed)
            assert not agent.state.in_air and agent.state.alt < 0.1
            assert autopilot.failure is None and not any("fail" in e for _, e in agent.events)
        finally:
            await autopilot.close()

    asyncio.run(scenario())
    assert "0 undecodable" in vehicle.stop()


def test_a_goto_the_vehicle_refuses_on_the_ground_is_tried_again_until_it_holds(vehicle, monkeypatch):
    """A task that reaches the UAV between arming and lift-off is refused
    (the vehicle is still on the ground); it must be sent again, not dropped
    with the UAV left hovering over its take-off point."""
    from bearcat.agents.uav import autopilot as autopilots

    monkeypatch.setattr(autopilots, "TAKE_OFF_WAIT", 0.0)  # send the goto at once, as a loaded machine would

    async def scenario():
        autopilot = MavsdkAutopilot(vehicle.url)
        await autopilot.connect(timeout=10.0)
        try:
            agent = _agent(autopilot, link_timeout=60.0)
            _start(agent)
            agent.handle(keys.uav_task(GAME, "q1"), _task(1, 30.0, 20.0), time.monotonic())
            await _fly(
                agent, 30.0, until=lambda s: math.hypot(*to_local(s.lat, s.lon, HOME[:2])) > 35.5 and s.speed < 0.3
            )
            east, north = to_local(agent.state.lat, agent.state.lon, HOME[:2])
            assert math.hypot(east - 30.0, north - 20.0) < 1.0
        finally:
            await autopilot.close()

    asyncio.run(scenario())


def test_mavsdk_client_steers_by_offboard_velocity_to_a_point(vehicle):
    async def scenario():
        autopilot = MavsdkAutopilot(vehicle.url)
        await autopilot.connect(timeout=10.0)
        try:
            agent = _agent(autopilot, link_timeout=60.0, steer="velocity", speed=6.0)
            _start(agent)
            await _fly(agent, 15.0, until=lambda s: s.in_air and s.alt > 4.5 and s.mode == "hold")
            agent.handle(keys.uav_task(GAME, "q1"), _task(1, 25.0, -10.0), time.monotonic())
            modes = set()

            def there(s):
                modes.add(s.mode)
                return math.dist(to_local(s.lat, s.lon, HOME[:2]), (25.0, -10.0)) < 1.0 and s.speed < 0.3

            await _fly(agent, 20.0, until=there)
            assert "offboard" in modes and autopilot.failure is None
            agent.handle(keys.uav_task(GAME, "q1"), _task(2, 0.0, 0.0, kind="land"), time.monotonic())
            await _fly(agent, 20.0, until=lambda s: not s.armed)
        finally:
            await autopilot.close()

    asyncio.run(scenario())


@pytest.mark.parametrize("failsafe", ["land", "hold"])
def test_a_silent_ground_station_triggers_the_failsafe(vehicle, failsafe):
    async def scenario():
        autopilot = MavsdkAutopilot(vehicle.url)
        await autopilot.connect(timeout=10.0)
        try:
            agent = _agent(autopilot, failsafe=failsafe, link_timeout=1.0)
            _start(agent)
            # The ground station keeps talking (the task, re-sent) while the UAV climbs and flies out...
            task = _task(1, 15.0, 0.0)
            talk = lambda now: [(keys.uav_task(GAME, "q1"), task)]  # noqa: E731
            await _fly(agent, 20.0, until=lambda s: s.in_air and to_local(s.lat, s.lon, HOME[:2])[0] > 14.0, feed=talk)
            assert agent.failsafe_at is None
            # ... then falls silent.
            if failsafe == "land":
                await _fly(agent, 20.0, until=lambda s: not s.armed)
            else:
                await _fly(
                    agent, 5.0, until=lambda s: agent.failsafe_at is not None and s.mode == "hold" and s.speed < 0.3
                )
                assert agent.state.in_air
            assert any(f"failsafe {failsafe}" in e for _, e in agent.events)
        finally:
            await autopilot.close()

    asyncio.run(scenario())


def test_ground_station_liveliness_loss_triggers_the_failsafe_at_once():
    autopilot = SimulatedAutopilot(HOME[:2], rng=np.random.default_rng(0))
    agent = _agent(autopilot, failsafe="return", link_timeout=60.0)
    agent.start(0.0)
    agent.handle(keys.control(GAME), Control(t=0.0, command="start"), 0.0)
    for k in range(100):
        agent.tick(k * 0.1)
    agent.peer(keys.alive(GAME, "walker", "attacker"), False, 10.0)
    assert agent.failsafe_at is None  # somebody else leaving is not a lost link
    agent.peer(keys.alive(GAME, "ground-station", "gs"), False, 10.0)
    assert agent.failsafe_at == 10.0 and autopilot.flight.sub == SubMode.RTL


def test_two_uavs_fly_at_once():
    vehicles = [Vehicle(sysid=1), Vehicle(sysid=2)]
    goals = [(20.0, 0.0), (0.0, -20.0)]

    async def one(v: Vehicle, goal):
        autopilot = MavsdkAutopilot(v.url, sysid=v.sysid)
        await autopilot.connect(timeout=10.0)
        try:
            agent = _agent(autopilot, link_timeout=60.0)
            _start(agent)
            await _fly(agent, 15.0, until=lambda s: s.in_air and s.alt > 4.5 and s.mode == "hold")
            agent.handle(keys.uav_task(GAME, "q1"), _task(1, *goal), time.monotonic())
            reached = lambda s: math.dist(to_local(s.lat, s.lon, HOME[:2]), goal) < 1.0 and s.speed < 0.3  # noqa: E731
            return await _fly(agent, 20.0, until=reached)
        finally:
            await autopilot.close()

    async def both():
        return await asyncio.gather(*(one(v, g) for v, g in zip(vehicles, goals)))

    try:
        arrivals = asyncio.run(both())
        assert abs(arrivals[0] - arrivals[1]) < 3.0  # flown side by side, not one after the other
    finally:
        for v in vehicles:
            v.stop()


def test_emulator_refuses_unknown_commands_at_once_and_survives_garbage(vehicle):
    """The 0.5 s is a requirement: MAVSDK resends a command it has no
    COMMAND_ACK for after about 0.5 s, so a slower answer would make the
    client see a timeout instead of UNSUPPORTED. The emulator answers in a
    millisecond or two; the rest is margin for a loaded machine."""
    client = mavutil.mavlink_connection(f"udpin:127.0.0.1:{vehicle.port}", source_system=245, source_component=190)
    try:
        assert client.wait_heartbeat(timeout=5) is not None
        hb = client.messages["HEARTBEAT"]
        assert hb.autopilot == mavutil.mavlink.MAV_AUTOPILOT_PX4 and hb.type == mavutil.mavlink.MAV_TYPE_QUADROTOR
        (address,) = client.clients  # the vehicle's socket
        rng = np.random.default_rng(0)
        for size in (1, 7, 300, 280):  # garbage from the client's own address, and a frame of noise
            client.port.sendto(rng.bytes(size), address)
        client.port.sendto(b"\xfd\x09\x00\x00\x00\x01\x01\x00\x00\x00" + rng.bytes(20), address)
        sent = time.monotonic()
        client.mav.command_long_send(vehicle.sysid, 1, mavutil.mavlink.MAV_CMD_DO_GRIPPER, 0, 1, 0, 0, 0, 0, 0, 0)
        ack = client.recv_match(type="COMMAND_ACK", blocking=True, timeout=2)
        assert ack is not None and ack.command == mavutil.mavlink.MAV_CMD_DO_GRIPPER
        assert ack.result == mavutil.mavlink.MAV_RESULT_UNSUPPORTED and time.monotonic() - sent < 0.5
        client.mav.param_request_read_send(vehicle.sysid, 1, b"MIS_TAKEOFF_ALT", -1)
        value = client.recv_match(type="PARAM_VALUE", blocking=True, timeout=2)
        assert value is not None and value.param_id == "MIS_TAKEOFF_ALT" and value.param_value == pytest.approx(2.5)
        assert client.wait_heartbeat(timeout=2) is not None  # still alive
    finally:
        client.close()
    out = vehicle.stop()
    bad = int(out.split(" undecodable")[0].rsplit(" ", 1)[1])
    assert bad >= 1, out  # counted and dropped


def test_camera_reports_an_opponent_inside_its_footprint_only():
    autopilot = SimulatedAutopilot(HOME[:2], rng=np.random.default_rng(0))
    agent = _agent(autopilot, link_timeout=60.0)
    agent.start(0.0)
    agent.handle(keys.control(GAME), Control(t=0.0, command="start"), 0.0)
    for k in range(60):
        agent.tick(k * 0.1)

    def seen(east, north, now):
        lat, lon = to_geodetic(east, north, HOME[:2])
        return agent.handle(keys.truth(GAME, "defender"), Truth(agent="defender", t=now, lat=lat, lon=lon), now)

    assert seen(12.0, 0.0, 6.0) == []  # outside r_q = 10 m
    sends = seen(6.0, 6.0, 6.1)
    assert len(sends) == 1 and sends[0].key == keys.detection(GAME, "q1") and sends[0].message.agent == "defender"
    assert seen(6.0, 6.0, 6.5) == []  # at most once a second per agent


def test_a_uav_peer_whose_vehicle_died_still_stops_when_told(tmp_path):
    """The launcher's stop reaches a UAV peer whose vehicle emulator died
    mid-flight: the landing it sends can never be answered, and the peer
    must exit anyway, within seconds, not wait to be killed."""
    import signal
    import socket
    import subprocess
    import sys

    from bearcat.bus.codec import encode
    from bearcat.bus.zenoh_session import ZenohSession, config

    def free(kind):
        with socket.socket(socket.AF_INET, kind) as s:
            s.bind(("127.0.0.1", 0))
            return s.getsockname()[1]

    port, vport = free(socket.SOCK_STREAM), free(socket.SOCK_DGRAM)
    with ZenohSession("launcher", config(listen=[f"tcp/127.0.0.1:{port}"], mode="router")) as launcher:
        vehicle = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "bearcat",
                "vehicle",
                "--connect",
                f"udpout:127.0.0.1:{vport}",
                "--home",
                "37.87,-122.26,0",
            ]
        )
        peer = subprocess.Popen(
            [
                *(sys.executable, "-m", "bearcat", "peer", "uav", "--scenario", "search", "--id", "q1"),
                *("--connect", f"tcp/127.0.0.1:{port}", "--mode", "client"),
                *("--vehicle", f"udpin://0.0.0.0:{vport}", "--sysid", "1", "--emulated"),
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        try:
            assert launcher.alive(keys.alive("search", "uav", "q1"), timeout=1.0) or _wait_alive(launcher, 30.0)
            launcher.put(keys.control("search"), encode(Control(t=time.time(), command="start", seq=1)))
            time.sleep(4.0)  # taking off
            vehicle.kill()
            vehicle.wait()
            time.sleep(1.0)
            launcher.put(keys.control("search"), encode(Control(t=time.time(), command="stop", seq=2)))
            told = time.monotonic()
            output, _ = peer.communicate(timeout=20)
            assert time.monotonic() - told < 8.0, output
            assert peer.returncode == 0 and "peer q1: stopped by the launcher" in output, output
        finally:
            for p in (peer, vehicle):
                if p.poll() is None:
                    p.send_signal(signal.SIGKILL)
                    p.wait()


def _wait_alive(session, seconds: float) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if session.alive(keys.alive("search", "uav", "q1"), timeout=0.5):
            return True
        time.sleep(0.2)
    return False
