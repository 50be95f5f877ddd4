"""Maneuver files (``data/maneuvers/*.toml``): the numbers of a designed
maneuver, read into the solver's dataclasses, and its solved sets on disk.

A maneuver file holds every number its design depends on, so a change to
any of them is a change to a file a reader can see, and its sets are cached
under a key that hashes the file's contents (with the scheme and the
package version). The cache shares the capture-the-flag sets' root and is
as safe to delete.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import tomllib
import zipfile
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Annotated

import msgspec
import numpy as np
from msgspec import Meta

from bearcat.agents.cache import cache_root, write_atomically
from bearcat.agents.ground_station.ctf_cache import solver_fingerprint
from bearcat.solvers.errors import InputError
from bearcat.solvers.grid import Grid
from bearcat.solvers.levelset.hji import ReachAvoidResult
from bearcat.solvers.maneuvers.backflip import Backflip, BackflipSets, SetProgress, TargetBox, design
from bearcat.solvers.maneuvers.planar_quad import Laws, Quadrotor
from bearcat.solvers.maneuvers.sets import Containment
from bearcat.validation import Invalid, convert

log = logging.getLogger(__name__)

FORMAT = 1
DEG = math.pi / 180

Positive = Annotated[float, Meta(gt=0)]
Share = Annotated[float, Meta(gt=0, le=1)]
Span = Annotated[list[float], Meta(min_length=2, max_length=2)]
Axis = Annotated[list[float], Meta(min_length=3, max_length=3, description="[lo, hi, points]")]


class _Table(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    pass


class _Head(_Table, frozen=True):
    name: str
    description: str = ""


class _Vehicle(_Table, frozen=True):
    mass: Positive
    gravity: Positive
    translational_drag: Annotated[float, Meta(ge=0)]
    rotational_drag: Annotated[float, Meta(ge=0)]
    inertia: Positive
    arm: Positive
    max_thrust: Positive


class _Noise(_Table, frozen=True):
    thrust: Share
    drift: Share
    torque_share: Share


class _Laws(_Table, frozen=True):
    impulse_acceleration: Positive
    impulse_rate_gain: Positive
    impulse_lift: Positive
    recovery_angle_gain: Positive
    recovery_rate_gain: Positive
    recovery_lift: Positive
    recovery_floor: Positive
    climb_lift: Positive


class _TurnOff(_Table, frozen=True):
    spin_down_time: Positive


class _Box(_Table, frozen=True):
    angle: Span
    rate: Span


class _Targets(_Table, frozen=True):
    T1: _Box
    T2: _Box
    T3: _Box
    hover: _Box


class _Horizons(_Table, frozen=True):
    impulse: Positive
    drift: Positive
    recovery: Positive


class _Safety(_Table, frozen=True):
    fall_rate: Positive
    start_height: Positive


class _Grids(_Table, frozen=True):
    angle: Axis
    rate: Axis
    height: Axis
    climb_rate: Axis


class _ManeuverFile(_Table, frozen=True):
    maneuver: _Head
    vehicle: _Vehicle
    noise: _Noise
    laws: _Laws
    turn_off: _TurnOff
    targets: _Targets
    horizons: _Horizons
    safety: _Safety
    grids: _Grids


@dataclass(frozen=True)
class Maneuver:
    """A maneuver file as read: its design and what the flight adds to it."""

    name: str
    description: str
    design: Backflip
    start_height: float
    source: str
    text: str


def builtin_dir():
    return resources.files("bearcat.scenarios") / "data" / "maneuvers"


def list_maneuvers() -> list[str]:
    return sorted(p.name[:-5] for p in builtin_dir().iterdir() if p.name.endswith(".toml"))


def load_maneuver(name_or_path: str | Path) -> Maneuver:
    """A built-in maneuver by name, or a maneuver file."""
    if isinstance(name_or_path, str) and name_or_path in list_maneuvers():
        source = f"{name_or_path}.toml"
        return parse_maneuver((builtin_dir() / source).read_text(encoding="utf-8"), source)
    path = Path(name_or_path)
    if not path.is_file():
        raise InputError(
            f"there is no maneuver {str(name_or_path)!r}: not a built-in one ({', '.join(list_maneuvers())}) nor a file"
        )
    try:
        return parse_maneuver(path.read_text(encoding="utf-8"), str(path))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path} cannot be read as a maneuver file: {exc}") from None


def parse_maneuver(text: str, source: str = "<maneuver>") -> Maneuver:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{source} is not valid TOML: {exc}") from None
    try:
        file = convert(data, _ManeuverFile)
        backflip = _backflip(file)
    except Invalid as exc:
        raise InputError(f"{source}: {exc}") from None
    except (InputError, ValueError) as exc:
        raise InputError(f"{source}: {exc}") from None
    return Maneuver(file.maneuver.name, file.maneuver.description, backflip, file.safety.start_height, source, text)


def with_torque_share(maneuver: Maneuver, share: float) -> Maneuver:
    """``maneuver`` with its rotational noise share replaced (the variation
    that shows how the thesis's 5 % would act as a full torque)."""
    if not 0 < share <= 1:
        raise InputError(f"a torque share must lie in (0, 1], got {share:g}")
    return replace(maneuver, design=replace(maneuver.design, torque_share=share))


def _backflip(file: _ManeuverFile) -> Backflip:
    v, n, law, t, g = file.vehicle, file.noise, file.laws, file.targets, file.grids
    return Backflip(
        vehicle=Quadrotor(**msgspec.structs.asdict(v)),
        laws=Laws(**{**msgspec.structs.asdict(law), "impulse_acceleration": law.impulse_acceleration * DEG}),
        thrust_noise=n.thrust,
        drift_noise=n.drift,
        torque_share=n.torque_share,
        spin_down_time=file.turn_off.spin_down_time,
        start=_target(t.hover, "targets.hover"),
        t1=_target(t.T1, "targets.T1"),
        t2=_target(t.T2, "targets.T2"),
        t3=_target(t.T3, "targets.T3"),
        impulse_horizon=file.horizons.impulse,
        drift_horizon=file.horizons.drift,
        recovery_horizon=file.horizons.recovery,
        fall_rate=file.safety.fall_rate,
        attitude_grid=_grid((g.angle, g.rate), (DEG, DEG), "grids.angle and grids.rate"),
        vertical_grid=_grid((g.height, g.climb_rate), (1.0, 1.0), "grids.height and grids.climb_rate"),
    )


def _target(b: _Box, where: str) -> TargetBox:
    try:
        return TargetBox((b.angle[0] * DEG, b.angle[1] * DEG), (b.rate[0] * DEG, b.rate[1] * DEG))
    except InputError:
        raise Invalid(where, f"needs lo < hi in angle and rate, got {b.angle} and {b.rate}") from None


def _grid(axes, scales, where: str) -> Grid:
    for lo, hi, points in axes:
        if not (lo < hi and points >= 11 and float(points).is_integer()):
            raise Invalid(
                where, f"each axis needs lo < hi and a whole number of at least 11 points, got {[lo, hi, points]}"
            )
    return Grid.spanning(
        tuple(a[0] * s for a, s in zip(axes, scales)),
        tuple(a[1] * s for a, s in zip(axes, scales)),
        tuple(int(a[2]) for a in axes),
    )


def set_key(maneuver: Maneuver, scheme: str) -> str:
    """The cache key of ``maneuver``'s sets: its design as solved (the file's
    numbers after any override), the scheme, the format and the code."""
    inputs = {"format": FORMAT, "code": solver_fingerprint(), "design": repr(maneuver.design), "scheme": scheme}
    return hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()[:32]


def load_or_design(
    maneuver: Maneuver,
    *,
    scheme: str = "weno5",
    root: Path | None = None,
    use_cache: bool = True,
    progress: SetProgress | None = None,
    device: str = "auto",
) -> tuple[BackflipSets, str]:
    """The maneuver's sets and where they came from (``"cache"`` or
    ``"solved"``), solved on ``device`` if not cached (no part of the key:
    the sets are the same on each)."""
    path = (root or cache_root()) / "maneuver" / f"{maneuver.name}-{set_key(maneuver, scheme)}.npz"
    if use_cache:
        loaded = _load(path, maneuver.design)
        if loaded is not None:
            return loaded, "cache"
    sets = design(maneuver.design, progress=progress, scheme=scheme, device=device)
    if use_cache:
        _store(path, sets)
    return sets, "solved"


def _store(path: Path, sets: BackflipSets) -> None:
    arrays = {f"capture_{k}": r.value for k, r in sets.capture.items()}
    arrays |= {f"unsafe_{k}": v for k, v in sets.unsafe.items()}
    arrays["reach"] = sets.reach
    arrays["lift_envelope"] = sets.lift_envelope
    meta = {
        "checks": [c.__dict__ for c in sets.checks],
        "turn_off": sets.turn_off,
        "alpha": sets.alpha,
        "times": sets.times,
        "runs": {k: [r.converged, r.converged_at, r.time, r.steps] for k, r in sets.capture.items()},
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    # numpy types savez's allow_pickle beside its **kwds; none of these names is that.
    write_atomically(path, lambda f: np.savez(f, meta=np.array(json.dumps(meta)), **arrays))  # type: ignore[arg-type]


def _load(path: Path, backflip: Backflip) -> BackflipSets | None:
    if not path.exists():
        return None
    try:
        with np.load(path) as data:
            meta = json.loads(str(data["meta"]))
            capture = {
                name: ReachAvoidResult(data[f"capture_{name}"], *meta["runs"][name])
                for name in ("recovery", "drift", "impulse")
            }
            unsafe = {k: data[f"unsafe_{k}"] for k in ("K1", "K2", "K3")}
            reach, envelope = data["reach"], data["lift_envelope"]
        for value in (*(r.value for r in capture.values()), reach):
            if value.shape != backflip.attitude_grid.shape:
                raise ValueError(f"an attitude set of shape {value.shape}")
        return BackflipSets(
            backflip,
            capture,
            reach,
            unsafe,
            [Containment(**c) for c in meta["checks"]],
            tuple(meta["turn_off"]),
            float(meta["alpha"]),
            meta["times"],
            envelope,
        )
    except (OSError, EOFError, ValueError, KeyError, TypeError, zipfile.BadZipFile) as exc:
        log.warning("cached maneuver sets %s are unreadable (%s); solving them again", path, exc)
        return None
