"""An opponent on the bus: a plain Zenoh client, none of bearcat's code,
that reads what it can and publishes whatever it likes, under any name."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import zenoh


class Intruder:
    """A Zenoh client of the router at ``endpoint``, optionally over TLS with
    the certificate ``cert``/``key`` from the authority ``ca``."""

    def __init__(self, endpoint: str, *, ca: Path | None = None, cert: Path | None = None, key: Path | None = None):
        c = zenoh.Config()
        c.insert_json5("mode", '"client"')
        c.insert_json5("connect/endpoints", json.dumps([endpoint]))
        c.insert_json5("scouting/multicast/enabled", "false")
        if ca is not None:
            tls = {"root_ca_certificate": str(ca)}
            if cert is not None:
                tls |= {"connect_certificate": str(cert), "connect_private_key": str(key), "enable_mtls": True}
            c.insert_json5("transport/link/tls", json.dumps(tls))
        self.session = zenoh.open(c)
        self.heard: list[tuple[str, bytes, bytes | None]] = []
        self._lock = threading.Lock()
        self._taps = []

    def __enter__(self) -> Intruder:
        return self

    def __exit__(self, *_exc) -> None:
        for tap in self._taps:
            tap.undeclare()
        self.session.close()

    def put(self, key: str, payload: bytes, attachment: bytes | None) -> None:
        self.session.put(key, payload, attachment=attachment)

    def tap(self, key_expr: str) -> None:
        """Keep every sample on ``key_expr`` it can read: (key, payload, attachment)."""

        def heard(sample: zenoh.Sample) -> None:
            attachment = sample.attachment.to_bytes() if sample.attachment is not None else None
            with self._lock:
                self.heard.append((str(sample.key_expr), sample.payload.to_bytes(), attachment))

        self._taps.append(self.session.declare_subscriber(key_expr, heard))

    def samples(self, prefix: str) -> list[tuple[str, bytes, bytes | None]]:
        with self._lock:
            return [h for h in self.heard if h[0].startswith(prefix)]
