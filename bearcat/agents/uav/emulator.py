"""The MAVLink vehicle emulator: one PX4 quadrotor on one UDP port.

A plain loop at ``RATE`` Hz: read whatever MAVLink arrived, let the
vehicle answer it, step the physics, send the telemetry that is due. It
sends to the address a ground station listens on (PX4 SITL's convention:
the vehicle ``udpout:`` to 127.0.0.1:14540 + i, the client
``udpin://0.0.0.0:14540 + i``), so a client written against PX4 connects
unchanged. Bytes that do not parse are counted and dropped; nothing a
client sends stops the vehicle.
"""

from __future__ import annotations

import logging
import os
import signal
import time
from dataclasses import dataclass

import numpy as np

os.environ.setdefault("MAVLINK20", "1")  # PX4 speaks MAVLink 2; pymavlink reads this at import
from pymavlink import mavutil

from bearcat.agents.uav.airframe import Airframe
from bearcat.agents.uav.flight import Flight
from bearcat.agents.uav.px4 import Px4Face

RATE = 50.0  # Hz of the physics and of polling the socket
log = logging.getLogger("bearcat.vehicle")


@dataclass
class Counts:
    received: int = 0
    bad: int = 0
    sent: int = 0


def serve(
    url: str,
    sysid: int,
    home: tuple[float, float, float],
    *,
    airframe: Airframe | None = None,
    start=(0.0, 0.0),
    seed: int = 0,
    stop=lambda: False,
    duration: float = float("inf"),
) -> Counts:
    """Run the vehicle until ``stop()`` is true, SIGTERM or SIGINT, or ``duration`` s.
    ``start`` is where it stands, in metres east/north of ``home``."""
    mavutil.set_dialect("common")
    conn = mavutil.mavlink_connection(url, source_system=sysid, source_component=1, dialect="common")
    flight = Flight(airframe or Airframe(), np.random.default_rng(seed), start=start)
    face = Px4Face(flight, sysid, home)
    counts = Counts()
    stopping = []
    for sig in (signal.SIGTERM, signal.SIGINT):
        try:
            signal.signal(sig, lambda *_: stopping.append(True))
        except ValueError:  # not the main thread: the caller stops us through ``stop``
            pass
    t0 = last = time.monotonic()
    log.info("vehicle %d on %s, home %.6f %.6f %.1f m", sysid, url, *home)
    try:
        while not stopping and not stop() and last - t0 < duration:
            now = time.monotonic()
            for msg in _drain(conn, counts):
                for reply in face.handle(msg, now - t0):
                    conn.mav.send(reply)
                    counts.sent += 1
            flight.step(now - t0, now - last)
            last = now
            if flight.note:
                log.info("vehicle %d: %s", sysid, flight.note)
                flight.note = ""
            for message in face.telemetry(now - t0):
                conn.mav.send(message)
                counts.sent += 1
            time.sleep(max(0.0, 1.0 / RATE - (time.monotonic() - now)))
    finally:
        conn.close()
    return counts


def _drain(conn, counts: Counts):
    while True:
        try:
            msg = conn.recv_msg()
        except Exception as error:  # a datagram pymavlink cannot even frame
            counts.bad += 1
            log.debug("dropped a datagram: %s", error)
            continue
        if msg is None:
            return
        if msg.get_type() == "BAD_DATA":
            counts.bad += 1
            continue
        counts.received += 1
        yield msg
