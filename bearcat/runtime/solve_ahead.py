"""Solve a scenario's game before its trials or peers start, or behind a
live game that started on provisional sets.

The ground station's guidance needs the game's winning sets; solved here,
they are in the cache before the first trial or peer asks, so no game waits
on a solve and a cache directory that refuses the write fails before
anything else runs. The caller draws the progress (the CLI's bars).

A live run need not wait for a large grid: its ground station may start
on provisional sets, solved in seconds, while ``SolveBehind`` solves the
game's own sets into the cache in a child process at the lowest priority
an ordinary process has (nice 19), so the game's peers keep the processor
they need, and yet the solve moves on a laptop kept busy by other work,
where one that ran only on idle processors would wait for that work to
end. The ground station takes those sets up once they are there.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import signal
import sys
import time
from collections.abc import Callable

Progress = Callable[[str, float, float, float], None]
"""``progress(name, t, horizon, change)``, as the solvers report a set's solve."""


def solve_ahead(scenario, netem: str, *, provisional: bool = False, progress: Progress | None = None) -> None:
    """Build the ground station of ``scenario`` under profile ``netem`` once,
    which solves (or loads) and caches what its guidance answers from. With
    ``provisional``, a game whose sets are not cached gets provisional ones."""
    from bearcat.netem.profiles import load_profile
    from bearcat.scenarios.cast import build_cast

    build_cast(
        scenario,
        load_profile(netem),
        scenario.seed,
        people=[],
        ground=True,
        ctf_progress=progress,
        provisional=provisional,
    )


WAITED = 4
"""Where in the shared array the launcher says it waits for the solve (1)."""

LOWEST = 19  # nice: the lowest priority of an ordinary process


class SolveBehind:
    """The ``awaited`` sets (``cast.AwaitedSets``) solved into the cache by
    a child process at the lowest priority, from the moment it is made.
    The child dies with this process. ``finish`` waits for it with a
    progress bar; ``stop`` ends it, leaving the sets for another run."""

    def __init__(self, awaited) -> None:
        self.awaited = awaited
        context = multiprocessing.get_context("spawn")  # the solver's threads do not survive a fork
        # The set's place in the stages, game time reached, horizon, change; and whether it is waited for.
        self._where = context.Array("d", 5)
        self._process = context.Process(
            target=_solve_behind,
            # Pickled here, unpickled after the child lowered its priority: loading
            # the game imports the solvers, a second of work the peers starting
            # beside it should not wait for.
            args=(pickle.dumps(awaited.game), awaited.stages, self._where),
            name=f"solve {awaited.game.grid_points}-point sets",
            daemon=True,
        )
        self._process.start()

    @property
    def pid(self) -> int | None:
        """The child's process number."""
        return self._process.pid

    @property
    def done(self) -> bool:
        return not self._process.is_alive()

    @property
    def solved(self) -> bool:
        """Whether the child ended having stored every set."""
        return self.done and self._process.exitcode == 0

    def finish(self, say: Callable[[str], None], progress: Progress | None = None) -> bool:
        """Wait for the sets, reporting the game time solved to ``progress``
        and telling ``say`` why; Ctrl-C stops the solve instead. Whether they
        were solved."""
        from bearcat.solvers.ctf.sets import STAGES

        if not self.done:
            grid = self.awaited.game.grid_points
            say(f"solving the {grid}-point sets so the next run starts on them (Ctrl-C leaves them for later)")
            self._where[WAITED] = 1.0
            _promote(self._process.pid)
            names = STAGES[self.awaited.stages]
            try:
                while not self.done:
                    k, t, horizon, change = self._where[:WAITED]
                    if horizon > 0 and progress is not None:
                        progress(names[int(k)], t, horizon, change)
                    time.sleep(0.2)
            except KeyboardInterrupt:
                self.stop()
            if not self.solved:
                say(f"the {grid}-point sets were left unsolved; the next run starts on provisional sets again")
        return self.solved

    def stop(self) -> None:
        if not self.done:
            self._process.terminate()
        self._process.join()


def compile_kernels_behind():
    """A child process, at the lowest priority, that fills numba's
    cache with the guidance's query kernels (``ctf.queries.compile_kernels``)
    and the walkers' look-ahead (``descent.compile_kernels``) while the
    launcher compiles and runs the solver on one processor. So a ground
    station peer of a fresh clone loads its kernels in a third of a second
    instead of compiling them for two before it says it is up, and a walker
    does not stand still for three at the start of its first game. Join it
    or terminate it; it dies with this process in any case."""
    context = multiprocessing.get_context("spawn")
    process = context.Process(target=_compile_kernels, name="compile the peers' kernels", daemon=True)
    process.start()
    return process


def _compile_kernels() -> None:
    _lowest()
    from bearcat.solvers.ctf import queries as ctf_queries
    from bearcat.solvers.marching import descent

    ctf_queries.compile_kernels()
    descent.compile_kernels()


def _lowest() -> None:
    """Give this child the lowest priority (the threads it starts inherit
    it), leave Ctrl-C to the launcher, and die with it."""
    os.setpriority(os.PRIO_PROCESS, 0, LOWEST)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the launcher's to handle
    from bearcat.netem.kernel.commands import die_with_parent

    die_with_parent()


def _promote(pid: int | None = None) -> None:
    """Give every thread of process ``pid`` (None: this one) the launcher's
    own priority: once the game is over somebody waits for the solve. The
    launcher promotes the child when it starts to wait; the child, having
    lowered itself, promotes itself if the launcher already waits, in case
    it did so after the launcher's promotion. Raising a priority takes
    privileges (root, or a nice limit); without them the solve goes on at
    the lowest one."""
    ordinary = os.getpriority(os.PRIO_PROCESS, os.getppid() if pid is None else 0)
    try:
        threads = os.listdir(f"/proc/{pid or 'self'}/task")
    except OSError:
        return  # gone, or no /proc
    for tid in threads:
        try:
            os.setpriority(os.PRIO_PROCESS, int(tid), ordinary)  # on Linux, one thread's
        except OSError:
            pass  # a thread that ended meanwhile, or no privilege: it stays at the lowest priority


def _solve_behind(pickled_game: bytes, stages: str, where) -> None:
    """The child's work: solve the game's ``stages`` into the cache, reporting
    in ``where``, at the lowest priority, so a peer never waits for it."""
    _lowest()
    if where[WAITED]:  # the launcher started waiting, and promoting us, before we lowered ourselves
        _promote()
    from bearcat.agents.ground_station.ctf_cache import load_or_solve
    from bearcat.solvers.ctf.sets import STAGES

    game = pickle.loads(pickled_game)
    names = STAGES[stages]

    def report(name: str, t: float, horizon: float, change: float) -> None:
        where[:WAITED] = [names.index(name), t, horizon, change]

    try:
        load_or_solve(game, stages, progress=report)
    except Exception as exc:  # the game goes on without them; say why once
        print(f"bearcat: the {game.grid_points}-point sets could not be solved: {exc}", file=sys.stderr)
        sys.exit(1)
