"""The UAV as a peer of the game: a quadrotor flown through an autopilot,
tasked by the ground station, used as an aerial camera (thesis 2, 6.2).

On the start command it takes off to its altitude; each task from the
ground station sends it somewhere (a search target or a waypoint), holds
it or lands it. It ``steer``s there by ``goto`` (the autopilot flies to the
point) or by ``velocity`` (offboard velocity setpoints ten times a second
on a braking curve toward the point, the way a companion computer steers).
Its telemetry goes out as fixes on its own fix key, so the
ground station and the phones see it like any agent. Its camera sees a
disk of radius ``r_q`` on the ground (V_Q of 6.2.2): an opponent whose
true position lies in it while the UAV flies is reported as a detection
(judged on truth in simulation, where the truth keys exist). When the game
ends it lands. A simulated or emulated vehicle's telemetry is the truth, and
goes out on its truth key too (``truth``), for the referee and the
recorder. If the ground station's liveliness token vanishes, or
nothing has come from it for ``link_timeout`` seconds while flying, it
applies its failsafe once (``hold``, ``return`` or ``land``), as PX4's
data-link-loss action does; a new task from the ground station takes it
back.
"""

from __future__ import annotations

import math
from typing import Literal, get_args

import numpy as np

from bearcat.agents.protocol import Send
from bearcat.agents.uav.autopilot import Autopilot, VehicleState
from bearcat.bus import keys
from bearcat.bus.messages import Control, Detection, Fix, GameState, Message, Truth, UavTask
from bearcat.maps.geodesy import to_local

Failsafe = Literal["hold", "return", "land"]
FAILSAFES: tuple[Failsafe, ...] = get_args(Failsafe)
Steering = Literal["goto", "velocity"]
STEERING: tuple[Steering, ...] = get_args(Steering)
BRAKING = 2.0  # m/s^2 the velocity steering plans to brake at


class UavAgent:
    role = "uav"

    def __init__(
        self,
        game: str,
        name: str,
        autopilot: Autopilot,
        *,
        altitude: float = 20.0,
        camera_radius: float = 15.0,
        watch: tuple[str, ...] = (),
        fix_rate: float = 2.0,
        failsafe: str = "hold",
        link_timeout: float = 5.0,
        truth: bool = False,
        steer: str = "goto",
        speed: float = 8.0,
    ) -> None:
        if failsafe not in FAILSAFES:
            raise ValueError(f"failsafe {failsafe!r} is not one of {', '.join(FAILSAFES)}")
        if steer not in STEERING:
            raise ValueError(f"steer {steer!r} is not one of {', '.join(STEERING)}")
        self.steer, self.speed = steer, float(speed)
        self.target: tuple[float, float, float] | None = None  # lat, lon, altitude of a velocity-steered task
        self.game, self.name = game, name
        self.autopilot = autopilot
        self.altitude = float(altitude)
        self.camera_radius = float(camera_radius)
        self.failsafe = failsafe
        self.link_timeout = float(link_timeout)
        self.truth = truth
        self.period = 0.1
        self.subscriptions = (
            keys.uav_task(game, name),
            keys.state(game),
            keys.control(game),
            *(keys.truth(game, agent) for agent in watch),
        )
        self.watches = (keys.every(game, "alive"),)
        self.state: VehicleState | None = None
        self.flying = False  # took off and not told to land
        self.ended = False
        self.failsafe_at: float | None = None
        self.events: list[tuple[float, str]] = []  # what the UAV did on its own, for the log and tests
        self._fix_every = 1.0 / fix_rate
        self._next_fix = 0.0
        self._seq = 0
        self._heard = -math.inf
        self._task_seq = -1
        self._seen: dict[str, float] = {}  # agent -> time of the last detection sent
        self._origin: tuple[float, float] | None = None

    # ------------------------------------------------------------------ agent protocol

    def start(self, now: float) -> list[Send]:
        self._heard = now
        return []

    def handle(self, key: str, message: Message, now: float) -> list[Send]:
        if isinstance(message, UavTask):
            self._heard = now
            if message.seq > self._task_seq:
                self._task_seq = message.seq
                self._task(message, now)
        elif isinstance(message, GameState):
            self._heard = now
            if message.phase == "running" and not self.flying and not self.ended:
                self._take_off(now)
            elif message.phase == "ended" and not self.ended:
                self.ended = True
                self._land(now, "the game is over")
        elif isinstance(message, Control):
            if message.command in ("start", "resume") and not self.flying and not self.ended:
                self._take_off(now)
            elif message.command == "stop" and not self.ended:
                self.ended = True
                self._land(now, "stopped")
        elif isinstance(message, Truth):
            return self._look(message, now)
        return []

    def tick(self, now: float) -> list[Send]:
        self.state = self.autopilot.update(now)
        if self.autopilot.failure:
            self.events.append((now, self.autopilot.failure))
            self.autopilot.failure = None
        lost = now - self._heard > self.link_timeout
        if lost and self.flying and not self.ended and self.failsafe_at is None:
            self._fail_safe(now, f"nothing from the ground station for {self.link_timeout:g} s")
        if self.target is not None and self.state is not None and self.state.in_air and self.failsafe_at is None:
            self.autopilot.velocity(*self._steering(self.state, self.target))
        s = self.state
        if s is None:
            return []
        out = []
        if self.truth:
            truth = Truth(agent=self.name, t=now, lat=s.lat, lon=s.lon, alt=s.alt, heading=s.heading)
            out.append(Send(keys.truth(self.game, self.name), truth))
        if now >= self._next_fix:
            self._next_fix = max(self._next_fix + self._fix_every, now)
            self._seq += 1
            fix = Fix(agent=self.name, seq=self._seq, t=now, lat=s.lat, lon=s.lon, alt=s.alt, heading=s.heading)
            out.append(Send(keys.fix(self.game, self.name), fix))
        return out

    def peer(self, key: str, alive: bool, now: float) -> list[Send]:
        parsed = keys.parse(key)
        if parsed.role == "ground-station" and not alive and self.flying and not self.ended:
            self._fail_safe(now, f"ground station {parsed.agent} is gone")
        return []

    # ------------------------------------------------------------------ flying

    def _task(self, task: UavTask, now: float) -> None:
        if self.ended:
            return
        if self.failsafe_at is not None:
            self.events.append((now, "the ground station is back"))
            self.failsafe_at = None
        self.target = None
        if task.kind == "land":
            self._land(now, "told to land")
        elif task.kind == "hold":
            self.autopilot.hold()
        elif self.flying and self.steer == "velocity":
            self.target = (task.lat, task.lon, task.alt if task.alt > 0 else self.altitude)
        elif self.flying:
            self.autopilot.goto(task.lat, task.lon, task.alt if task.alt > 0 else self.altitude)

    def _steering(self, s: VehicleState, target: tuple[float, float, float]) -> tuple[float, float, float]:
        """The velocity toward ``target``: as fast as the vehicle may go while
        it can still brake before the point; climb or descend to its altitude."""
        lat, lon, alt = target
        east, north = to_local(lat, lon, self._frame(s))
        here = to_local(s.lat, s.lon, self._frame(s))
        d = np.array([east - here[0], north - here[1]])
        distance = float(np.hypot(*d))
        speed = min(self.speed, math.sqrt(2 * BRAKING * distance), distance)
        horizontal = d / distance * speed if distance > 1e-6 else np.zeros(2)
        return float(horizontal[0]), float(horizontal[1]), float(np.clip(alt - s.alt, -1.5, 2.0))

    def _frame(self, s: VehicleState) -> tuple[float, float]:
        """One local frame for all distances, centred where the UAV was first
        seen (a frame per position would cost a projection set-up per look)."""
        self._origin = self._origin or (s.lat, s.lon)
        return self._origin

    def _take_off(self, now: float) -> None:
        self.flying = True
        self.autopilot.take_off(self.altitude)
        self.events.append((now, f"taking off to {self.altitude:g} m"))

    def _land(self, now: float, why: str) -> None:
        self.target = None
        if self.flying:
            self.autopilot.land()
            self.events.append((now, f"landing: {why}"))
        self.flying = False

    def _fail_safe(self, now: float, why: str) -> None:
        self.failsafe_at = now
        self.target = None
        self.events.append((now, f"failsafe {self.failsafe}: {why}"))
        {"hold": self.autopilot.hold, "return": self.autopilot.return_home, "land": self.autopilot.land}[
            self.failsafe
        ]()
        if self.failsafe == "land":
            self.flying = False

    # ------------------------------------------------------------------ the camera

    def _look(self, truth: Truth, now: float) -> list[Send]:
        """A detection when ``truth`` lies in the camera's footprint (once a second per agent)."""
        s = self.state
        if s is None or not s.in_air or now - self._seen.get(truth.agent, -math.inf) < 1.0:
            return []
        east, north = to_local(truth.lat, truth.lon, self._frame(s))
        ue, un = to_local(s.lat, s.lon, self._frame(s))
        if np.hypot(east - ue, north - un) > self.camera_radius:
            return []
        self._seen[truth.agent] = now
        seen = Detection(uav=self.name, t=now, agent=truth.agent, lat=truth.lat, lon=truth.lon)
        return [Send(keys.detection(self.game, self.name), seen)]
