"""Time bearcat's HJI level-set solver against hj_reachability on the same
problem, scheme, grid, CFL number, boundary rule and horizon.

    python benchmarks/hji.py            # 45^4 over 6 time units, then ours to convergence and at 65^4,
                                        # then the two-stage game at 45^4 and 65^4 with query timings
    python benchmarks/hji.py --quick    # 21^4 over 2 time units, a few seconds per run
    python benchmarks/hji.py --game     # only the two-stage game at 45^4 and 65^4
    python benchmarks/hji.py --device cuda   # on a CUDA GPU: ours against hj_reachability on the same GPU,
                                             # the two-stage game at 45^4, 65^4 and 101^4, the kernels' compile
    python benchmarks/hji.py --threads  # ours at 1, 2, 4, 8 and 16 threads (as many as the machine has cores),
                                        # beside the memory bandwidth those threads reach

Each of our solves runs twice, on the full grid and by the local band
(``solve_reach_avoid(local=True)``), with the node updates of each (node
time steps) beside the seconds, since the machine is shared and noisy; the
two-stage game ends with the local band's targets, met or not.

Needs ``pip install jax hj-reachability`` (JAX on the CPU; with ``--device
cuda``, JAX with CUDA, and ``pip install 'bearcat[cuda]'``). Every solve runs in
its own process so that its peak resident memory can be read from
``getrusage``; both solvers are warmed up inside that process first (numba's
cache load, JAX's compilation), so the seconds are solving only.

The problem is the flag-return stage of 1 vs 1 capture-the-flag (thesis
3.3.1) in an open square ``[-5, 5]^2`` per agent: the attacker (control, axes
0-1) must reach the return strip ``x >= 4`` along one edge without coming
within ``r_c = 0.5`` of the defender (disturbance, axes 2-3), who forfeits by
entering the strip; both at speed 1. hj_reachability gets the same reach-avoid
update (``max(min(J, l), -g)`` after every step), the same ghost extrapolation
(``solvers.levelset.hji``: values rise beyond the attacker's edges and fall beyond the
defender's), its own WENO5 + TVD-RK3 (``"very_high"``) or first-order upwind +
Euler (``"low"``) and its default global Lax-Friedrichs dissipation, which for
these dynamics equals ours.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

HJ_ACCURACY = {"first": "low", "weno5": "very_high"}
CAPTURE_RADIUS = 0.5
STRIP = 4.0


def problem(n: int):
    """Target ``l`` and avoid ``g`` on the ``n^4`` grid, float32."""
    from bearcat.solvers.grid import Grid

    grid = Grid.spanning((-5.0,) * 4, (5.0,) * 4, (n,) * 4)
    xa, ya, xd, yd = np.meshgrid(*grid.axes(), indexing="ij", sparse=True)
    target = np.broadcast_to(np.minimum(STRIP - xa, STRIP - xd), grid.shape).astype(np.float32)
    avoid = (np.hypot(xa - xd, ya - yd) - CAPTURE_RADIUS).astype(np.float32)
    return grid, target, avoid


def run_ours(n: int, scheme: str, horizon: float, tol: float, local: bool, device: str = "cpu") -> dict:
    from bearcat.solvers.levelset.hamiltonians import SimpleMotion
    from bearcat.solvers.levelset.hji import solve_reach_avoid

    grid, target, avoid = problem(n)
    game = SimpleMotion.pursuit(1.0, 1.0)
    small, small_target, small_avoid = problem(9)
    # Against hj_reachability the steps must be the same arithmetic, so the
    # monotone clamp (which hj_reachability lacks) is off there; the
    # convergence runs (tol > 0) use the solver's default.
    monotone = tol > 0
    settings = dict(scheme=scheme, monotone=monotone, local=local, device=device)
    warm = time.perf_counter()
    solve_reach_avoid(small, game, small_target, small_avoid, horizon=0.1, **settings)
    warm_up = time.perf_counter() - warm
    start = time.perf_counter()
    result = solve_reach_avoid(grid, game, target, avoid, horizon=horizon, tol=tol, **settings)
    seconds = time.perf_counter() - start
    return {
        "seconds": seconds,
        "steps": result.steps,
        "node_updates": result.node_updates,
        "time": result.time,
        "converged_at": result.converged_at,
        "set": result.reach_avoid_set,
        "warm_up": warm_up,
        "device": result.device,
    }


def _hj_edges(sign: float):
    import jax.numpy as jnp

    def pad(x, width):
        ramp = jnp.arange(width, 0, -1)
        left = x[0] + sign * jnp.abs(x[1] - x[0]) * ramp
        right = x[-1] + sign * jnp.abs(x[-1] - x[-2]) * ramp[::-1]
        return jnp.concatenate([left, x, right])

    return pad


def run_hj(n: int, scheme: str, horizon: float) -> dict:
    import hj_reachability as hj
    import jax
    import jax.numpy as jnp

    class Pursuit(hj.ControlAndDisturbanceAffineDynamics):
        def __init__(self):
            super().__init__("min", "max", hj.sets.Ball(jnp.zeros(2), 1.0), hj.sets.Ball(jnp.zeros(2), 1.0))

        def open_loop_dynamics(self, state, time):
            return jnp.zeros(4)

        def control_jacobian(self, state, time):
            return jnp.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0], [0.0, 0.0]])

        def disturbance_jacobian(self, state, time):
            return jnp.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])

    _, target, avoid = problem(n)
    up, down = _hj_edges(1.0), _hj_edges(-1.0)
    grid = hj.Grid.from_lattice_parameters_and_boundary_conditions(
        hj.sets.Box(jnp.full(4, -5.0), jnp.full(4, 5.0)), (n,) * 4, boundary_conditions=(up, up, down, down)
    )
    target_j, avoid_j = jnp.asarray(target), jnp.asarray(avoid)
    settings = hj.SolverSettings.with_accuracy(
        HJ_ACCURACY[scheme], value_postprocessor=lambda t, v: jnp.maximum(jnp.minimum(v, target_j), -avoid_j)
    )
    initial = jnp.maximum(target_j, -avoid_j)
    dynamics = Pursuit()
    hj.solve(settings, dynamics, grid, jnp.array([0.0, -1e-3]), initial, progress_bar=False).block_until_ready()
    start = time.perf_counter()
    values = hj.solve(settings, dynamics, grid, jnp.array([0.0, -horizon]), initial, progress_bar=False)
    final = np.asarray(values[-1].block_until_ready())
    seconds = time.perf_counter() - start
    dt = settings.CFL_number / (4 / float(grid.spacings[0]))
    return {
        "seconds": seconds,
        "steps": int(np.ceil(horizon / dt - 1e-9)),
        "time": horizon,
        "converged_at": None,
        "set": final <= 0,
        "device": f"JAX on {jax.devices()[0].platform}: {jax.devices()[0].device_kind}",
    }


GAME_MAP, GAME_SPEED, GAME_CAPTURE_RADIUS, GAME_HORIZON = "field-50", 3.0, 2.5, 60.0


def run_game(n: int, local: bool, mask: str, device: str = "cpu") -> dict:
    """The two-stage game (R_A, then W_A) on field-50 to convergence, then
    the guidance queries of one ground-station tick on it; W_A saved to
    ``mask``, and the share of the grid near the front measured on the
    full grid's sets (on the CPU only: on a GPU the census would outlast
    the solve many times over)."""
    from bearcat.maps import load_map
    from bearcat.maps.ctf import ctf_geometry
    from bearcat.solvers.ctf.queries import CtfQueries
    from bearcat.solvers.ctf.sets import Rules, solve_ctf
    from bearcat.solvers.levelset.hji import required_bytes

    rules = Rules(GAME_SPEED, GAME_SPEED, GAME_CAPTURE_RADIUS, GAME_HORIZON, GAME_HORIZON)
    game_map = load_map(GAME_MAP)
    solve_ctf(ctf_geometry(game_map, 9), rules, "both", local=local, device=device)  # load the compiled kernels
    geometry = ctf_geometry(game_map, n)
    start = time.perf_counter()
    solution = solve_ctf(geometry, rules, "both", local=local, device=device)
    seconds = time.perf_counter() - start
    queries = CtfQueries(solution)
    rng = np.random.default_rng(0)
    states = rng.uniform(0.0, 50.0, size=(200, 4))
    timings = {"evaluate": [], "slices": [], "polygons": []}
    for k, state in enumerate(states):
        a, d = state[:2], state[2:]
        t0 = time.perf_counter()
        queries.evaluate(a, d)
        t1 = time.perf_counter()
        rd, ra = queries.defender_region_values(a), queries.attacker_region_values(d)
        t2 = time.perf_counter()
        queries.polygons(rd, "defender"), queries.polygons(ra, "attacker")
        t3 = time.perf_counter()
        if k >= 10:  # the first calls load compiled code
            for key, dt in zip(timings, (t1 - t0, t2 - t1, t3 - t2)):
                timings[key].append(dt * 1e3)
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # before the census's own arrays
    np.save(mask, solution.sets["win"].attacker_wins)
    return {
        "seconds": seconds,
        "peak_mb": peak_mb,
        "node_updates": sum(s.node_updates for s in solution.sets.values()),
        "sets": {
            name: {
                "converged_at": s.converged_at,
                "steps": s.steps,
                "wins": float(s.attacker_wins.mean()),
                "near_front": None if local or device != "cpu" else band_census(s.time_to_win, s.time),
            }
            for name, s in solution.sets.items()
        },
        "query_ms": {key: float(np.median(v)) for key, v in timings.items()},
        "device": solution.sets["win"].device,
        "solver_gb": required_bytes(geometry.joint_grid(), record_tstar=True, record_gradient=False) / 1e9,
        "set_mb": 2 * geometry.joint_grid().size * 4 / 1e6,
    }


CENSUS_RADII = (3, 5)


def band_census(tstar: np.ndarray, horizon: float, samples: int = 16) -> dict:
    """How much of the grid lies near the front, averaged over the solve:
    what a narrow-band method (Adalsteinsson and Sethian; Peng et al.) would
    have to update. The set at time t is ``{T* <= t}``, so the full solve's
    T* replays its front. ``nodes r``: nodes within r cells of the front
    along every axis at once (a band cut to the node, its radius the WENO5
    stencil's three cells plus a margin); ``rows r``: whole rows within r
    rows of a row the front crosses (a band the stage kernel runs at full
    speed, as its loops stay long)."""
    from scipy import ndimage

    shares = {f"{kind} {r}": [] for kind in ("nodes", "rows") for r in CENSUS_RADII}
    for t in np.linspace(0.0, horizon, samples):
        inside = tstar <= t
        front = (inside & ~ndimage.binary_erosion(inside, border_value=1)) | (
            ~inside & ~ndimage.binary_erosion(~inside, border_value=1)
        )
        crossed = {"nodes": front.view(np.uint8), "rows": front.any(axis=-1).view(np.uint8)}
        for kind, band0 in crossed.items():
            for r in CENSUS_RADII:
                band = band0
                for axis in range(band.ndim):
                    band = ndimage.maximum_filter1d(band, 2 * r + 1, axis=axis, mode="constant")
                shares[f"{kind} {r}"].append(float(band.mean()))
    return {key: float(np.mean(v)) for key, v in shares.items()}


def child(args) -> None:
    if args.solver == "game":
        print(json.dumps(run_game(args.n, args.local, args.mask, args.device)))
        return
    if args.solver == "compile":
        print(json.dumps(run_compile()))
        return
    if args.solver == "bandwidth":
        print(json.dumps({"gb_s": triad_gb_s()}))
        return
    if args.solver == "ours":
        out = run_ours(args.n, args.scheme, args.horizon, args.tol, args.local, args.device)
    else:
        out = run_hj(args.n, args.scheme, args.horizon)
    np.save(args.mask, out.pop("set"))
    out["peak_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps(out))


def measure(
    solver: str,
    n: int,
    scheme: str,
    horizon: float,
    tol: float,
    mask: str,
    local: bool = False,
    device: str = "cpu",
    env: dict | None = None,
) -> dict:
    cmd = [
        sys.executable,
        __file__,
        "--child",
        solver,
        "--n",
        str(n),
        "--scheme",
        scheme,
        "--horizon",
        str(horizon),
        "--tol",
        str(tol),
        "--mask",
        mask,
        "--device",
        device,
        *(["--local"] if local else []),
    ]
    env = dict(os.environ if env is None else env)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [ROOT, os.environ.get("PYTHONPATH")]))
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if done.returncode != 0:
        raise SystemExit(f"{solver} {scheme} n={n} failed:\n{done.stderr}")
    return json.loads(done.stdout.strip().splitlines()[-1])


ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def row(label: str, n: int, r: dict, speedup: str = "", against_full: str = "", disagree: str = "") -> str:
    ns = r["seconds"] / r["node_updates"] * 1e9
    conv = f"{r['converged_at']:.1f}" if r.get("converged_at") else "-"
    return (
        f"{label:<28} {n:>3}^4 {r['time']:>6.1f} {conv:>6} {r['steps']:>5} {r['seconds']:>8.1f} "
        f"{r['node_updates'] / 1e6:>9.0f} {ns:>7.1f} {r['peak_mb']:>8.0f} {speedup:>7} {against_full:>13} {disagree:>9}"
    )


def fewer_and_faster(full: dict, local: dict) -> str:
    """How many times fewer node updates and seconds the local band took."""
    return f"{full['node_updates'] / max(local['node_updates'], 1):.2f}x/{full['seconds'] / local['seconds']:.2f}x"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="21^4 over 2 time units")
    parser.add_argument("--game", action="store_true", help="only the two-stage capture-the-flag game")
    parser.add_argument(
        "--device",
        choices=("cpu", "cuda"),
        default="cpu",
        help="cpu (default): ours on every core against hj_reachability on the CPU; cuda: both on this machine's GPU",
    )
    parser.add_argument(
        "--threads", action="store_true", help="ours at 1, 2, 4, 8 and 16 threads, beside the memory bandwidth"
    )
    parser.add_argument(
        "--child", choices=("ours", "hj", "game", "compile", "bandwidth"), dest="solver", help=argparse.SUPPRESS
    )
    parser.add_argument("--n", type=int, default=45, help=argparse.SUPPRESS)
    parser.add_argument("--scheme", default="weno5", help=argparse.SUPPRESS)
    parser.add_argument("--horizon", type=float, default=6.0, help=argparse.SUPPRESS)
    parser.add_argument("--tol", type=float, default=0.0, help=argparse.SUPPRESS)
    parser.add_argument("--mask", help=argparse.SUPPRESS)
    parser.add_argument("--local", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.solver:
        child(args)
        return
    if args.device == "cuda":
        on_the_gpu(args.quick, args.game)
        return
    if args.threads:
        scaling(args.quick)
        return

    if not args.game:
        compare(args.quick)
        print()
    game(args.quick)


THREADS = (1, 2, 4, 8, 16)
TARGET_16_OVER_2 = 6.0
BYTES_PER_UPDATE = 44
"""The least memory traffic of one node update (one node, one time step) of
WENO5 + TVD-RK3 reach-avoid in float32, if every stencil neighbour comes
from cache: stage 1 reads v and writes out (8 bytes), stages 2 and 3 read
v and u0 and write out (12 each), the last also reads the target and the
avoid set (8) and T* (4). Writes that first read their line (write-allocate)
add 12 more."""
TRIAD_N = 1 << 26
"""Elements of each float32 array of the bandwidth probe: 256 MB, far beyond any cache."""


def triad_gb_s(repeats: int = 5) -> float:
    """Memory bandwidth that ``numba.get_num_threads()`` threads reach on the
    triad ``a = b + s c`` (STREAM's, 12 bytes an element), the best of ``repeats``."""
    import numba

    @numba.njit(parallel=True, cache=True)
    def triad(a, b, c, s):
        for i in numba.prange(a.size):
            a[i] = b[i] + s * c[i]

    a, b, c = (np.full(TRIAD_N, v, np.float32) for v in (0.0, 1.0, 2.0))
    triad(a, b, c, np.float32(3.0))
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        triad(a, b, c, np.float32(3.0))
        best = min(best, time.perf_counter() - start)
    return 12 * TRIAD_N / best / 1e9


def scaling(quick: bool) -> None:
    """Ours on the flag return at 1, 2, 4, 8 and 16 threads (those the
    machine has cores for), each in its own process, with the bandwidth the
    same threads reach on the triad: whether the kernels are bound by memory."""
    n, horizon = (21, 2.0) if quick else (45, 6.0)
    cores = os.cpu_count() or 1
    counts = [k for k in THREADS if k <= cores]
    print(
        f"flag return, {n}^4 over {horizon:g} time units, WENO5 + TVD-RK3, float32, on {cores} cores; "
        f"traffic at the least {BYTES_PER_UPDATE} bytes a node update"
    )
    print(
        f"{'threads':>7} {'seconds':>8} {'M upd/s':>8} {'vs 1':>6} {'vs 2':>6} {'GB/s moved':>10} "
        f"{'triad GB/s':>10} {'share':>6}"
    )
    rates = {}
    with tempfile.TemporaryDirectory() as tmp:
        for k in counts:
            env = {**os.environ, "NUMBA_NUM_THREADS": str(k)}
            r = measure("ours", n, "weno5", horizon, 0.0, os.path.join(tmp, "set.npy"), env=env)
            triad = measure("bandwidth", n, "weno5", horizon, 0.0, os.path.join(tmp, "unused.npy"), env=env)["gb_s"]
            rates[k] = r["node_updates"] / r["seconds"]
            moved = rates[k] * BYTES_PER_UPDATE / 1e9
            against_two = f"{rates[k] / rates[2]:.2f}x" if 2 in rates else "-"
            print(
                f"{k:>7} {r['seconds']:>8.2f} {rates[k] / 1e6:>8.1f} {rates[k] / rates[counts[0]]:>5.2f}x "
                f"{against_two:>6} {moved:>10.1f} {triad:>10.1f} {moved / triad:>5.0%}",
                flush=True,
            )
    left = [k for k in THREADS if k > cores]
    if left:
        print(f"not run: {', '.join(map(str, left))} threads, on a machine of {cores} cores")
    else:
        ratio = rates[16] / rates[2]
        print(
            f"target: 16 threads at least {TARGET_16_OVER_2:g}x as fast as 2: {ratio:.2f}x, "
            f"{'met' if ratio >= TARGET_16_OVER_2 else 'not met'}"
        )
    print(
        "GB/s moved: node updates a second x the least traffic of one; share: of the triad's bandwidth at the "
        "same threads. A share near 100 % says the kernels are bound by memory, well below it by arithmetic."
    )


def compare(quick: bool) -> None:
    """Ours, full grid and local band, against hj_reachability on one
    problem, then ours to convergence and at 65^4."""
    n, horizon = (21, 2.0) if quick else (45, 6.0)
    print(
        f"flag-return set on [-5,5]^2 per agent, return strip x >= {STRIP}, r_c = {CAPTURE_RADIUS}, "
        f"equal speeds, CFL 0.75, float32, {os.cpu_count()} cores"
    )
    print(
        f"{'solver':<28} {'grid':>5} {'horizon':>6} {'conv':>6} {'steps':>5} {'seconds':>8} {'updates M':>9} "
        f"{'ns/upd':>7} {'peak MB':>8} {'speedup':>7} {'fewer/faster':>13} {'disagree':>9}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        masks = {key: os.path.join(tmp, f"{key}.npy") for key in ("hj", "full", "local")}
        for scheme in ("first", "weno5"):
            theirs = measure("hj", n, scheme, horizon, 0.0, masks["hj"])
            ours = {local: measure("ours", n, scheme, horizon, 0.0, masks[KIND[local]], local) for local in KIND}
            theirs["node_updates"] = theirs["steps"] * n**4
            sets = {key: np.load(path) for key, path in masks.items()}
            print(row(f"hj_reachability {scheme}", n, theirs), flush=True)
            for local, r in ours.items():
                speedup = f"{theirs['seconds'] / r['seconds']:.1f}x"
                if local:
                    disagree = float(np.mean(sets["local"] != sets["full"]))
                    print(
                        row(
                            f"bearcat {scheme}, local",
                            n,
                            r,
                            speedup,
                            fewer_and_faster(ours[False], r),
                            f"{disagree:.2e}",
                        )
                    )
                else:
                    disagree = float(np.mean(sets["full"] != sets["hj"]))
                    print(row(f"bearcat {scheme}, full", n, r, speedup, "", f"{disagree:.2e}"), flush=True)
        for scheme in ("first", "weno5"):
            conv = {local: measure("ours", n, scheme, 30.0, 0.01, masks[KIND[local]], local) for local in KIND}
            for local, r in conv.items():
                label = f"bearcat {scheme}, {KIND[local]}, tol .01"
                print(row(label, n, r, "", fewer_and_faster(conv[False], r) if local else ""), flush=True)
        if not quick:
            big = {local: measure("ours", 65, "weno5", 1.0, 0.0, masks[KIND[local]], local) for local in KIND}
            for local, r in big.items():
                label = f"bearcat weno5, {KIND[local]} (memory)"
                print(row(label, 65, r, "", fewer_and_faster(big[False], r) if local else ""), flush=True)
    print(
        "updates M: millions of node time steps; ns/upd: nanoseconds per node update; speedup: hj_reachability's "
        "seconds over ours; fewer/faster: the full grid's node updates and seconds over the local band's; "
        "disagree: fraction of nodes whose membership differs from hj_reachability's set (full grid) or from "
        "the full grid's (local band)"
    )


KIND = {False: "full", True: "local"}

# The local band's targets on the two-stage game.
TARGET_FEWER, TARGET_FASTER, TARGET_45_S, TARGET_65_S, TARGET_65_MB = 4.0, 3.0, 20.0, 90.0, 876.0


def game(quick: bool) -> None:
    """The two-stage game at 45^4 and 65^4 (21^4 when quick), full grid and
    local band: time, node updates, peak memory, queries, the share of the
    grid near the front, then the targets."""
    print(
        f"two-stage capture-the-flag on {GAME_MAP} (R_A then W_A), WENO5 to convergence, speeds {GAME_SPEED} m/s, "
        f"r_c {GAME_CAPTURE_RADIUS} m, horizons {GAME_HORIZON} s; guidance query medians over 190 random states"
    )
    print(
        f"{'grid':>6} {'solve':>6} {'seconds':>8} {'updates M':>9} {'fewer/faster':>13} {'peak MB':>8} "
        f"{'R_A conv s':>10} {'W_A conv s':>10} {'differ':>7} {'value ms':>9} {'slices ms':>9} {'polys ms':>9}"
    )
    runs = {}
    for n_game in (21,) if quick else (45, 65):
        with tempfile.TemporaryDirectory() as tmp:
            masks = {local: os.path.join(tmp, f"win-{KIND[local]}.npy") for local in KIND}
            runs[n_game] = {local: measure("game", n_game, "weno5", 0.0, 0.0, masks[local], local) for local in KIND}
            differ = int(np.sum(np.load(masks[False]) != np.load(masks[True])))
        full = runs[n_game][False]
        for local, r in runs[n_game].items():
            conv = [r["sets"][k]["converged_at"] for k in ("return", "win")]
            q = r["query_ms"]
            print(
                f"{n_game:>4}^4 {KIND[local]:>6} {r['seconds']:>8.1f} {r['node_updates'] / 1e6:>9.0f} "
                f"{fewer_and_faster(full, r) if local else '':>13} {r['peak_mb']:>8.0f} "
                + " ".join(f"{c:>10.1f}" if c else f"{'-':>10}" for c in conv)
                + f" {differ if local else '':>7} {q['evaluate']:>9.3f} {q['slices']:>9.3f} {q['polygons']:>9.3f}",
                flush=True,
            )
        for name in ("return", "win"):
            near = full["sets"][name]["near_front"]
            print(
                f"{'':>6} {'R_A' if name == 'return' else 'W_A'} near the front, share of the grid over the solve: "
                + ", ".join(f"{key} {100 * share:.0f} %" for key, share in near.items()),
                flush=True,
            )
    print(
        "fewer/faster: the full grid's node updates and seconds over the local band's; differ: W_A nodes on which "
        "the local band and the full grid disagree; near the front: nodes within r cells of it along every axis at "
        "once, rows within r rows of a row it crosses (band_census)"
    )
    if not quick:
        print_targets(runs)


def print_targets(runs: dict) -> None:
    full, local = runs[45][False], runs[45][True]
    fewer, faster = full["node_updates"] / local["node_updates"], full["seconds"] / local["seconds"]
    checks = [
        ("node updates at 45^4", f">= {TARGET_FEWER:g}x fewer", f"{fewer:.2f}x", fewer >= TARGET_FEWER),
        ("wall time at 45^4", f">= {TARGET_FASTER:g}x less", f"{faster:.2f}x", faster >= TARGET_FASTER),
        ("two-stage game at 45^4", f"< {TARGET_45_S:g} s", f"{local['seconds']:.1f} s", local["seconds"] < TARGET_45_S),
    ]
    big = runs[65][True]
    checks += [
        ("two-stage game at 65^4", f"< {TARGET_65_S:g} s", f"{big['seconds']:.1f} s", big["seconds"] < TARGET_65_S),
        ("peak memory at 65^4", f"<= {TARGET_65_MB:g} MB", f"{big['peak_mb']:.0f} MB", big["peak_mb"] <= TARGET_65_MB),
    ]
    print("targets of the local band on the two-stage game:")
    for what, target, measured, met in checks:
        print(f"  {what:<24} {target:<14} measured {measured:>9}: {'met' if met else 'not met'}")


# --- on a GPU ---

# The targets of the CUDA backend (issue 34).
GPU_TARGET_RATIO = 10.0  # the flag return at 45^4, horizon 6: times faster than hj_reachability on the same GPU
GPU_TARGET_GAME_S = {45: 0.5, 65: 2.0, 101: 20.0}  # the two-stage game to convergence
GPU_TARGET_COMPILE_S = 15.0  # the kernels' first compile


def gpu_or_refusal() -> str:
    """The GPU's name, or exit with one sentence saying why none will do."""
    from bearcat.solvers.errors import InputError
    from bearcat.solvers.levelset.devices import choose_device

    try:
        chosen = choose_device("cuda")
    except InputError as exc:
        raise SystemExit(f"benchmarks/hji.py --device cuda: {exc}") from None
    if chosen.gpu is None or chosen.gpu.simulated:
        raise SystemExit(
            "benchmarks/hji.py --device cuda: numba's CUDA simulator is on (NUMBA_ENABLE_CUDASIM), and its timings "
            "mean nothing; unset it on a machine with a GPU"
        )
    return chosen.gpu.name


def run_compile() -> dict:
    """Seconds of the first CUDA solve in this process, on a 9^4 grid: the
    kernels' compile if numba's cache is empty, their load if not."""
    from bearcat.solvers.levelset.hamiltonians import SimpleMotion
    from bearcat.solvers.levelset.hji import solve_reach_avoid

    grid, target, avoid = problem(9)
    game = SimpleMotion.pursuit(1.0, 1.0)
    start = time.perf_counter()
    for scheme in ("first", "weno5"):
        solve_reach_avoid(grid, game, target, avoid, horizon=0.1, scheme=scheme, device="cuda")
    return {"seconds": time.perf_counter() - start}


def compile_times(tmp: str) -> tuple[float, float]:
    """The kernels' first compile, into an empty numba cache, and their load
    from that cache in a second process; each includes the CPU kernels that
    a solve also runs (the ghost fill), so each is an upper bound."""
    env = dict(os.environ, NUMBA_CACHE_DIR=os.path.join(tmp, "numba-cache"))
    first = measure("compile", 9, "weno5", 0.1, 0.0, os.path.join(tmp, "unused.npy"), env=env)
    again = measure("compile", 9, "weno5", 0.1, 0.0, os.path.join(tmp, "unused.npy"), env=env)
    return first["seconds"], again["seconds"]


def on_the_gpu(quick: bool, game_only: bool) -> None:
    """Ours on the GPU against hj_reachability on the same GPU, the
    two-stage game, the compile, then the targets."""
    name = gpu_or_refusal()
    n, horizon = (21, 2.0) if quick else (45, 6.0)
    print(f"on {name}: ours (numba-cuda) and hj_reachability (JAX) on the same GPU, float32, CFL 0.75")
    checks = []
    with tempfile.TemporaryDirectory() as tmp:
        compiled, cached = compile_times(tmp)
        print(f"kernels' first compile {compiled:.1f} s (an empty cache), then {cached:.1f} s from the cache")
        checks.append(
            ("first compile", f"< {GPU_TARGET_COMPILE_S:g} s", f"{compiled:.1f} s", compiled < GPU_TARGET_COMPILE_S)
        )
        if not game_only:
            print(
                f"{'flag return':<26} {'grid':>5} {'horizon':>7} {'steps':>5} {'seconds':>8} {'ns/upd':>7} "
                f"{'ratio':>6} {'disagree':>9}  device"
            )
            for scheme in ("first", "weno5"):
                masks = {key: os.path.join(tmp, f"{key}.npy") for key in ("hj", "ours")}
                theirs = measure("hj", n, scheme, horizon, 0.0, masks["hj"])
                ours = measure("ours", n, scheme, horizon, 0.0, masks["ours"], device="cuda")
                disagree = float(np.mean(np.load(masks["hj"]) != np.load(masks["ours"])))
                ratio = theirs["seconds"] / ours["seconds"]
                for label, r in (("hj_reachability", theirs), ("bearcat", ours)):
                    ns = r["seconds"] / (r["steps"] * n**4) * 1e9
                    print(
                        f"{label + ' ' + scheme:<26} {n:>3}^4 {horizon:>7g} {r['steps']:>5} {r['seconds']:>8.3f} "
                        f"{ns:>7.2f} {ratio if label == 'bearcat' else 1.0:>5.1f}x {disagree:>9.2e}  {r['device']}",
                        flush=True,
                    )
                if not theirs["device"].startswith("JAX on gpu"):
                    print(f"  hj_reachability ran on {theirs['device']}, not the GPU: install JAX with CUDA to compare")
                elif scheme == "weno5" and not quick:
                    met = ratio >= GPU_TARGET_RATIO
                    checks.append(("flag return at 45^4", f">= {GPU_TARGET_RATIO:g}x hj", f"{ratio:.1f}x", met))
        print(
            f"{'two-stage game':<26} {'grid':>5} {'seconds':>8} {'R_A conv':>8} {'W_A conv':>8} {'GPU GB':>7} "
            f"{'set MB':>7}  device"
        )
        for n_game in (21,) if quick else (45, 65, 101):
            r = measure("game", n_game, "weno5", 0.0, 0.0, os.path.join(tmp, "win.npy"), device="cuda")
            conv = [r["sets"][k]["converged_at"] for k in ("return", "win")]
            print(
                f"{'bearcat weno5':<26} {n_game:>3}^4 {r['seconds']:>8.2f} "
                + " ".join(f"{c:>8.1f}" if c else f"{'-':>8}" for c in conv)
                + f" {r['solver_gb']:>7.2f} {r['set_mb']:>7.0f}  {r['device']}",
                flush=True,
            )
            if n_game in GPU_TARGET_GAME_S:
                target = GPU_TARGET_GAME_S[n_game]
                checks.append(
                    (f"two-stage game at {n_game}^4", f"< {target:g} s", f"{r['seconds']:.2f} s", r["seconds"] < target)
                )
    print(
        "ns/upd: nanoseconds per node update; ratio: hj_reachability's seconds over ours; disagree: the share of "
        "nodes whose membership differs from hj_reachability's; GPU GB: the arrays a solve keeps on the GPU "
        "(values, snapshot, target, avoid, T*); set MB: one solved set's value and T* on the host"
    )
    print("targets of the CUDA backend:")
    for what, target, measured, met in checks:
        print(f"  {what:<26} {target:<14} measured {measured:>9}: {'met' if met else 'not met'}")


if __name__ == "__main__":
    main()
