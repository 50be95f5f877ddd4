"""Calibrations on disk: one JSON file per game and network profile, in the cache.

A calibration is data, never a constant in code (DESIGN.md, "Guidance
under uncertainty"). It is keyed by what its scores depend on: the game's
sets (their cache keys hold the map, the grid, the rules and the solvers'
code), the network profile the games were played on, every number of it,
and the share of wrong goes it bounds; and the parts of the trackers a
study switched off (``guidance.ablate``), which change what is scored.
Like the sets, a calibration is safe to delete; ``bearcat calibrate`` makes
it again.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
from pathlib import Path

from bearcat.agents.cache import cache_root, write_atomically
from bearcat.agents.ground_station.calibration import Calibration
from bearcat.agents.ground_station.ctf_cache import CtfGame
from bearcat.agents.ground_station.tracker import TRACKER_ABLATIONS
from bearcat.netem.profiles import Profile

log = logging.getLogger(__name__)

__all__ = ["calibrate_command", "calibration_key", "calibration_path", "load_calibration", "store_calibration"]


def calibration_key(game: CtfGame, profile: Profile, alpha: float, ablate: tuple[str, ...] = ()) -> str:
    inputs: dict = {
        "alpha": alpha,
        "sets": [game.set_key("return"), game.set_key("win")],
        "profile": json.loads(json.dumps(dataclasses.asdict(profile), default=repr)),
    }
    tracker = sorted(set(ablate) & set(TRACKER_ABLATIONS))
    if tracker:
        inputs["tracker ablated"] = tracker
    return hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()[:32]


def calibration_path(
    game: CtfGame, profile: Profile, alpha: float, ablate: tuple[str, ...] = (), root: Path | None = None
) -> Path:
    return (root or cache_root()) / "calibration" / f"{calibration_key(game, profile, alpha, ablate)}.json"


def load_calibration(
    game: CtfGame, profile: Profile, alpha: float, ablate: tuple[str, ...] = (), root: Path | None = None
) -> Calibration | None:
    """The stored calibration of ``game`` on ``profile`` at ``alpha``, its
    trackers less ``ablate``; None if there is none, or if its file is
    damaged (said in the log)."""
    path = calibration_path(game, profile, alpha, ablate, root)
    try:
        return Calibration.from_json(json.loads(path.read_text(encoding="utf-8")))
    except FileNotFoundError:
        return None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        log.warning("calibration %s cannot be read (%s); calibrate again with bearcat calibrate", path, exc)
        return None


def store_calibration(
    calibration: Calibration, game: CtfGame, profile: Profile, ablate: tuple[str, ...] = (), root: Path | None = None
) -> Path:
    """Write ``calibration`` where ``load_calibration`` finds it; its path."""
    path = calibration_path(game, profile, calibration.alpha, ablate, root)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(calibration.to_json(), indent=1) + "\n"
    write_atomically(path, lambda f: f.write(text.encode()))
    return path


def calibrate_command(scenario: str, profile: str, ablate: tuple[str, ...] = ()) -> str:
    """The command that makes the calibration of ``scenario`` on ``profile``, its trackers less ``ablate``."""
    tracker = sorted(set(ablate) & set(TRACKER_ABLATIONS))
    return " ".join([f"bearcat calibrate {scenario} --netem {profile}", *(f"--ablate {part}" for part in tracker)])
