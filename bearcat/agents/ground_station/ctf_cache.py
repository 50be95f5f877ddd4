"""Solved capture-the-flag sets on disk, so the ground station and the CLI
solve a game once and load it in milliseconds afterwards.

Each set (R_A, F_A, W_A) is two ``.npy`` files, its value and its
time-to-win, memory-mapped on load, with a ``.json`` beside them saying how
its solve went. Its key hashes everything
that decides its values: the map's full GeoJSON, the grid, the speeds,
capture radius and horizon that set depends on, the scheme, tolerance and
precision, the file format, and the code that solves it
(``solver_fingerprint``); W_A's key includes R_A's.
So two games that share a flag-return stage share its file, and any change
to the inputs misses the cache rather than loading a stale answer (a change
to a solver's comments or docstrings alone does not). The
directory is safe to delete; a damaged entry is logged and solved again.

A set whose value holds NaN or infinities (a solver that overflowed), or
whose time-to-win holds NaN or negative times, is never stored or handed
out: a solve that gives one raises an InputError naming the game, and such
an entry already on disk (written before this check) counts as damaged and
is solved again, since the cache holds nothing a new solve cannot restore.

A process keeps the last few games it loaded whole from the cache, each
with the identity, size and time of its files: a study or a benchmark
plays game after game on the same sets, and reading and checking them
again (a third of a short game's run) gives what it gave the last time,
unless a file changed, which its stamp shows.
"""

from __future__ import annotations

import ast
import contextlib
import dataclasses
import fcntl
import functools
import hashlib
import json
import logging
import math
import os
from dataclasses import asdict, dataclass
from importlib import metadata
from pathlib import Path

import numba
import numpy as np

import bearcat.maps
import bearcat.solvers
from bearcat.agents.cache import cache_root, write_atomically
from bearcat.maps import Map
from bearcat.maps.ctf import ctf_geometry
from bearcat.maps.geojson import dumps
from bearcat.solvers.ctf.sets import DEFAULT_TOL, STAGES, CtfSolution, ProgressCallback, Rules, SetSolution, solve_ctf
from bearcat.solvers.errors import InputError

log = logging.getLogger(__name__)

FORMAT = 2
RECENT = 8
"""Games loaded whole from the cache that a process keeps, with their files' stamps."""
_recent: dict[tuple, tuple[tuple, Solved]] = {}


@dataclass(frozen=True)
class CtfGame:
    """One capture-the-flag game as a user names it."""

    map: Map
    grid_points: int
    rules: Rules
    scheme: str = "weno5"
    tol: float = DEFAULT_TOL
    dtype: str = "float32"
    local: bool = False
    # Where a set is solved ("auto", "cpu", "cuda"): the sets are the same on
    # each, so the device is no part of a game's identity or its cache key.
    device: str = dataclasses.field(default="auto", compare=False)

    def set_key(self, name: str) -> str:
        """The cache key of set ``name`` (``return``, ``capture`` or ``win``)."""
        horizon = self.rules.return_time if name == "return" else self.rules.capture_time
        rules = {k: v for k, v in asdict(self.rules).items() if k not in ("return_time", "capture_time")}
        inputs = {
            "format": FORMAT,
            "code": solver_fingerprint(),
            "set": name,
            "map": dumps(self.map, units="metres"),
            "grid_points": self.grid_points,
            "rules": rules,
            "horizon": horizon,
            "scheme": self.scheme,
            "tol": self.tol,
            "dtype": self.dtype,
            "after": self.set_key("return") if name == "win" else None,
        }
        if self.local:  # full-grid keys stay as they were
            inputs["local"] = True
        return hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()[:32]


@dataclass(frozen=True)
class Solved:
    """A solution and, per set, where it came from (``"cache"`` or ``"solved"``) and its file."""

    solution: CtfSolution
    sources: dict[str, str]
    paths: dict[str, Path]


def load_or_solve(
    game: CtfGame,
    stages: str = "both",
    *,
    root: Path | None = None,
    use_cache: bool = True,
    progress: ProgressCallback | None = None,
) -> Solved:
    """The sets of ``stages``, from the cache where present, solved (and
    stored) where not. Processes after the same sets take turns (peers of
    parallel runs, workers of a study): one solves, the others then load."""
    directory = (root or cache_root()) / "ctf"
    if not use_cache:
        return _load_or_solve(game, stages, directory, False, progress)
    recent = (game, stages, directory, solver_fingerprint())
    held = _recent.get(recent)
    if held is not None and held[0] == _stamps(held[1].paths):
        return held[1]
    with turn(game, stages, root=root):
        found = _load_or_solve(game, stages, directory, True, progress)
    stamps = _stamps(found.paths)
    if stamps is not None and all(source == "cache" for source in found.sources.values()):
        _recent.pop(recent, None)
        _recent[recent] = (stamps, found)
        while len(_recent) > RECENT:
            _recent.pop(next(iter(_recent)))
    return found


def _stamps(paths: dict[str, Path]) -> tuple | None:
    """The identity, size and modification time of every file of the sets at
    ``paths``; None if one is missing."""
    try:
        return tuple(
            (s.st_ino, s.st_size, s.st_mtime_ns)
            for path in paths.values()
            for s in (os.stat(f) for f in (path, _tstar_path(path), path.with_suffix(".json")))
        )
    except OSError:
        return None


def turn(game: CtfGame, stages: str, *, root: Path | None = None):
    """The turn to solve ``game``'s ``stages`` (a context manager): while
    one process holds it, another after the same sets waits for it."""
    names = "-".join(game.set_key(name) for name in STAGES.get(stages, ()))
    return _turn((root or cache_root()) / "ctf" / f".{hashlib.sha256(names.encode()).hexdigest()[:16]}.lock")


def stored(game: CtfGame, stages: str = "both", *, root: Path | None = None) -> bool:
    """Whether the cache has an entry for every set of ``stages`` (whole or
    damaged: loading tells), found without reading any."""
    directory = (root or cache_root()) / "ctf"
    return all(path.with_suffix(".json").exists() for path in _paths(game, stages, directory).values())


def cached(game: CtfGame, stages: str = "both", *, root: Path | None = None) -> Solved | None:
    """The sets of ``stages`` if every one of them is in the cache, else
    None; never solves, never waits for a process that is solving them (an
    entry is whole once its metadata is there), so it can be asked often.
    A damaged entry counts as one not there yet, without a word: asked once
    a second, a warning would repeat until whoever solves the sets, and
    says so, replaces it."""
    if not stored(game, stages, root=root):
        return None
    directory = (root or cache_root()) / "ctf"
    geometry = ctf_geometry(game.map, game.grid_points)
    known, paths = _loaded(game, stages, directory, geometry, quiet=True)
    if len(known) < len(paths):
        return None
    return Solved(_solution(game, stages, geometry, known), dict.fromkeys(known, "cache"), paths)


@contextlib.contextmanager
def _turn(lock: Path):
    """Hold ``lock`` (an exclusive flock) while inside; a cache that cannot
    hold one (read-only, on a file system without locks) is used unguarded."""
    try:
        lock.parent.mkdir(parents=True, exist_ok=True)
        held = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError:
        yield
        return
    try:
        try:
            fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            log.info("%s: another process is solving these sets; waiting to load them", lock.parent)
            fcntl.flock(held, fcntl.LOCK_EX)
        except OSError:
            pass
        yield
    finally:
        os.close(held)


def _load_or_solve(
    game: CtfGame, stages: str, directory: Path, use_cache: bool, progress: ProgressCallback | None
) -> Solved:
    geometry = ctf_geometry(game.map, game.grid_points)
    known, paths = _loaded(game, stages, directory, geometry) if use_cache else ({}, _paths(game, stages, directory))
    sources = dict.fromkeys(known, "cache")
    solution = _solution(game, stages, geometry, known, progress)
    for name, solved in solution.sets.items():
        if name not in known:
            flaw = _flaw(solved.value, solved.time_to_win)
            if flaw is not None:
                r = game.rules
                raise InputError(
                    f"solving set {name!r} on map {game.map.name} gave a set whose {flaw}, so it is neither cached "
                    f"nor used: speeds {r.attacker_speed:g} and {r.defender_speed:g} m/s, capture radius "
                    f"{r.capture_radius:g} m and horizons {r.capture_time:g} and {r.return_time:g} s on a "
                    f"{game.grid_points}-point grid are beyond what the solver resolves"
                )
            sources[name] = "solved"
            if use_cache:
                _store(paths[name], solved)
    return Solved(solution, sources, paths)


def _paths(game: CtfGame, stages: str, directory: Path) -> dict[str, Path]:
    return {name: directory / f"{game.set_key(name)}.npy" for name in STAGES.get(stages, ())}


def _loaded(
    game: CtfGame, stages: str, directory: Path, geometry, *, quiet: bool = False
) -> tuple[dict[str, SetSolution], dict[str, Path]]:
    """The sets of ``stages`` the cache holds whole, and where each one is or
    goes; a damaged one is passed over with a warning, unless ``quiet``."""
    paths = _paths(game, stages, directory)
    shape = geometry.joint_grid().shape
    known = {name: found for name, path in paths.items() if (found := _load(path, shape, quiet)) is not None}
    return known, paths


def _solution(game: CtfGame, stages: str, geometry, known: dict, progress: ProgressCallback | None = None):
    """``game`` solved for ``stages``, taking the ``known`` sets as they are."""
    return solve_ctf(
        geometry,
        game.rules,
        stages,
        scheme=game.scheme,
        dtype=np.dtype(game.dtype),
        tol=game.tol,
        known=known,
        progress=progress,
        local=game.local,
        device=game.device,
    )


def _flaw(value: np.ndarray, time_to_win: np.ndarray | None) -> str | None:
    """What makes a set unusable, or None: a value that is not finite
    everywhere, a time-to-win with NaN or below zero (inf is "never").
    Reductions, not masks, so a memory-mapped set is read once without a copy."""
    low, high = float(np.min(value)), float(np.max(value))
    if not (math.isfinite(low) and math.isfinite(high)):
        return "value holds NaN or infinite numbers"
    if time_to_win is not None and not float(np.min(time_to_win)) >= 0:
        return "time-to-win holds NaN or negative times"
    return None


def solver_fingerprint() -> str:
    """What cached numbers depend on besides their inputs: the package
    version, numpy's and numba's, and a hash of the code of the solvers
    and of the map geometry (every module of both: whatever a solve may
    run). A checkout that changes a solver between two releases (an
    editable install after a pull) then misses the cache instead of
    loading sets the old code solved; one that changes only comments or
    docstrings keeps it."""
    return _fingerprint(tuple(Path(p.__path__[0]) for p in (bearcat.solvers, bearcat.maps)))


@functools.cache
def _fingerprint(packages: tuple[Path, ...]) -> str:
    try:
        version = metadata.version("bearcat")
    except metadata.PackageNotFoundError:
        version = "unknown"
    paths = [(package, path) for package in packages for path in sorted(package.rglob("*.py"))]
    as_written = hashlib.sha256()
    for package, path in paths:
        as_written.update(path.relative_to(package.parent).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    source = _without_text(paths, as_written.hexdigest())
    return f"{version} numpy {np.__version__} numba {numba.__version__} source {source[:16]}"


def _without_text(paths: list[tuple[Path, Path]], as_written: str) -> str:
    """The hash of the code of ``paths`` without comments and docstrings.
    Parsing every module takes most of a second, which every process that
    opens the cache (each peer, each study worker) would pay; the hash of
    the files as written takes milliseconds, so the answer is kept under it
    in the cache directory, and parsing happens once per change of the code."""
    kept = cache_root() / "code" / as_written
    with contextlib.suppress(OSError, UnicodeDecodeError):
        known = kept.read_text()
        if len(known) == 64 and all(c in "0123456789abcdef" for c in known):
            return known
    source = hashlib.sha256()
    for package, path in paths:
        source.update(path.relative_to(package.parent).as_posix().encode() + b"\0" + _code(path).encode() + b"\0")
    digest = source.hexdigest()
    with contextlib.suppress(OSError):  # a cache directory that refuses writes only costs the parse again
        kept.parent.mkdir(parents=True, exist_ok=True)
        write_atomically(kept, lambda f: f.write(digest.encode()))
    return digest


def _code(path: Path) -> str:
    """What module ``path`` does, without what only its reader sees: its
    syntax tree, which holds no comments and no line numbers, with every
    string that stands alone as a statement (docstrings) taken out."""
    tree = ast.parse(path.read_bytes(), str(path))
    for node in ast.walk(tree):
        for field in ("body", "orelse", "finalbody"):
            statements = getattr(node, field, None)
            if isinstance(statements, list) and any(_is_text(s) for s in statements):
                setattr(node, field, [s for s in statements if not _is_text(s)] or [ast.Pass()])
    return ast.dump(tree)


def _is_text(statement: ast.AST) -> bool:
    return (
        isinstance(statement, ast.Expr)
        and isinstance(statement.value, ast.Constant)
        and isinstance(statement.value.value, str)
    )


def _load(path: Path, shape: tuple[int, ...], quiet: bool = False) -> SetSolution | None:
    meta_path = path.with_suffix(".json")
    if not (path.exists() and meta_path.exists()):
        return None
    try:
        meta = json.loads(meta_path.read_text())
        value = np.load(path, mmap_mode="r")
        time_to_win = np.load(_tstar_path(path), mmap_mode="r")
        for array in (value, time_to_win):
            if array.shape != shape:
                raise ValueError(f"shape {array.shape}, expected {shape}")
        flaw = _flaw(value, time_to_win)
        if flaw is not None:
            raise ValueError(f"its {flaw}")
        return SetSolution(
            meta["name"],
            value,
            bool(meta["converged"]),
            meta["converged_at"],
            float(meta["time"]),
            int(meta["steps"]),
            time_to_win,
        )
    except (OSError, EOFError, ValueError, KeyError, TypeError) as exc:
        if not quiet:
            log.warning("cached set %s is unreadable (%s); solving it again", path, exc)
        return None


def _tstar_path(path: Path) -> Path:
    return path.with_name(path.stem + ".tstar.npy")


def _store(path: Path, solved: SetSolution) -> None:
    """Write value, time-to-win, then metadata, each through a temporary
    file renamed into place, so a reader never sees half a file and an entry
    without its metadata counts as missing."""
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {
        "name": solved.name,
        "converged": solved.converged,
        "converged_at": solved.converged_at,
        "time": solved.time,
        "steps": solved.steps,
    }
    for target, write in (
        (path, lambda f: np.save(f, np.asarray(solved.value))),
        (_tstar_path(path), lambda f: np.save(f, np.asarray(solved.time_to_win))),
        (path.with_suffix(".json"), lambda f: f.write(json.dumps(meta).encode())),
    ):
        write_atomically(target, write)
