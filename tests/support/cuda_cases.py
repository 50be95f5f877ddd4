"""Problems the CUDA kernels solve beside the CPU's, each in a process of
its own (``tests/test_hji_cuda.py`` says why):

    python -m tests.support.cuda_cases OUT.npz CASE SCHEME [OPTIONS_JSON]

solves ``CASE`` with ``SCHEME`` on device ``"cpu"`` and on device ``"cuda"``
and writes both results to ``OUT.npz``: ``value``, ``tstar`` and
``gradient`` of each (``cpu_value``, ``cuda_tstar``, ...) and a JSON
``meta`` with each solve's steps, times and device. The grids are tiny:
numba's CUDA simulator runs a kernel's threads as Python.
"""

from __future__ import annotations

import json
import sys

import numba
import numpy as np

from bearcat.solvers.grid import Grid
from bearcat.solvers.levelset.hamiltonians import Ball, Box, ControlAffine, Player, SimpleMotion


@numba.njit(cache=True)
def rotating_and_pushed(x, f0, G, K):
    """x' = 0.5 (-y, x) + u + (0.3, 0.2) d."""
    f0[0] = -0.5 * x[1]
    f0[1] = 0.5 * x[0]
    G[0, 0], G[0, 1], G[1, 0], G[1, 1] = 1.0, 0.0, 0.0, 1.0
    K[0, 0], K[1, 0] = 0.3, 0.2


@numba.njit(cache=True)
def drifting_both_ways(x, f0, G, K):
    """x' = (0.2, 0) + u + d."""
    f0[0] = 0.2
    f0[1] = 0.0
    for i in range(2):
        for j in range(2):
            G[i, j] = 1.0 if i == j else 0.0
            K[i, j] = 1.0 if i == j else 0.0


def plane(n: int = 15) -> Grid:
    return Grid.spanning((-1.0, -1.0), (1.0, 1.0), (n, n))


def runner():
    """One control player on the plane, an obstacle beside the target."""
    grid = plane()
    x, y = grid.mesh()
    game = SimpleMotion((Player((0, 1), 1.0, "control"),))
    return grid, game, np.hypot(x - 0.4, y) - 0.3, np.hypot(x + 0.1, y + 0.1) - 0.25


def speed_map():
    """The runner, slower on the western half and in a strip."""
    grid, _, target, avoid = runner()
    x, y = grid.mesh()
    speed = np.where(x < 0, 0.5, 1.0) * np.where(np.abs(y - 0.5) < 0.2, 0.3, 1.0)
    return grid, SimpleMotion((Player((0, 1), speed, "control"),)), target, avoid


def line_pursuit():
    """Attacker (control, axis 0) against defender (disturbance, axis 1) on a
    line: reach x_a >= 0.6 without coming within 0.2 of the defender."""
    grid = plane()
    xa, xd = grid.mesh()
    return grid, SimpleMotion.pursuit(1.0, 0.8, dims=1), 0.6 - xa, np.abs(xa - xd) - 0.2


def square_pursuit():
    """The flag return of ``benchmarks/hji.py`` on a 6^4 grid: the attacker
    (axes 0-1) reaches the strip x_a >= 4 avoiding capture within 1.5 by the
    defender (axes 2-3), who forfeits by entering the strip."""
    grid = Grid.spanning((-5.0,) * 4, (5.0,) * 4, (6,) * 4)
    xa, ya, xd, yd = np.meshgrid(*grid.axes(), indexing="ij", sparse=True)
    target = np.broadcast_to(np.minimum(4.0 - xa, 4.0 - xd), grid.shape)
    return grid, SimpleMotion.pursuit(1.0, 1.0), target, np.hypot(xa - xd, ya - yd) - 1.5


def affine_ball():
    """Rotating dynamics, a ball of controls against a box of disturbance."""
    grid = plane()
    x, y = grid.mesh()
    game = ControlAffine(rotating_and_pushed, control=Ball((0.0, 0.0), 1.0), disturbance=Box((-1.0,), (1.0,)))
    return grid, game, np.hypot(x - 0.3, y) - 0.3, None


def affine_box():
    """A drift, a box of controls against a box of disturbance."""
    grid = plane()
    x, y = grid.mesh()
    game = ControlAffine(
        drifting_both_ways, control=Box((-1.0, -0.5), (2.0, 0.5)), disturbance=Box((-0.25, -0.1), (0.25, 0.1))
    )
    return grid, game, np.maximum(np.abs(x), np.abs(y)) - 0.3, np.hypot(x + 0.5, y - 0.5) - 0.2


CASES = {
    "runner": runner,
    "speed-map": speed_map,
    "line-pursuit": line_pursuit,
    "square-pursuit": square_pursuit,
    "affine-ball": affine_ball,
    "affine-box": affine_box,
}


def solve(case: str, scheme: str, options: dict) -> tuple[dict, dict]:
    from bearcat.solvers.levelset.hji import solve_reach_avoid

    grid, game, target, avoid = CASES[case]()
    settings = {"horizon": 0.5, "record_tstar": True, "tol": 0.0} | options
    arrays, meta = {}, {}
    for device in ("cpu", "cuda"):
        result = solve_reach_avoid(grid, game, target, avoid, scheme=scheme, device=device, **settings)
        arrays[f"{device}_value"] = result.value
        if result.tstar is not None:
            arrays[f"{device}_tstar"] = result.tstar
        if result.tstar_gradient is not None:
            arrays[f"{device}_gradient"] = result.tstar_gradient
        meta[device] = {
            "steps": result.steps,
            "time": result.time,
            "converged_at": result.converged_at,
            "node_updates": result.node_updates,
            "device": result.device,
            "dt": result.time / result.steps,
        }
    return arrays, meta


def solve_game(scheme: str, options: dict) -> tuple[dict, dict]:
    """The two-stage capture-the-flag game (R_A, then W_A) on a 6-point arena."""
    from bearcat.solvers.ctf.sets import CtfGeometry, Rules, solve_ctf

    grid = Grid.spanning((0.0, 0.0), (10.0, 10.0), (6, 6))
    x, y = grid.mesh()
    geometry = CtfGeometry(
        grid,
        blocked=np.full(grid.shape, 30.0),
        flag=np.hypot(x - 6.0, y - 2.0) - 2.5,
        home=8.0 - y,
        terrain=np.ones(grid.shape),
    )
    rules = Rules(capture_radius=2.0, capture_time=options.get("horizon", 3.0), return_time=options.get("horizon", 3.0))
    arrays, meta = {}, {}
    for device in ("cpu", "cuda"):
        solution = solve_ctf(geometry, rules, "both", scheme=scheme, device=device)
        meta[device] = {}
        for name, found in solution.sets.items():
            arrays[f"{device}_{name}_value"] = found.value
            arrays[f"{device}_{name}_tstar"] = found.time_to_win
            meta[device][name] = {
                "steps": found.steps,
                "time": found.time,
                "converged_at": found.converged_at,
                "device": found.device,
                "dt": found.time / found.steps,
            }
    return arrays, meta


def main(argv: list[str]) -> None:
    out, case, scheme = argv[:3]
    options = json.loads(argv[3]) if len(argv) > 3 else {}
    if "dtype" in options:
        options["dtype"] = np.dtype(options["dtype"])
    arrays, meta = solve_game(scheme, options) if case == "ctf" else solve(case, scheme, options)
    np.savez(out, meta=np.array(json.dumps(meta)), **arrays)


if __name__ == "__main__":
    main(sys.argv[1:])
