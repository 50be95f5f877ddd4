"""The CUDA backend of the level-set solver (``solvers.levelset.cuda``) against
the CPU's, and how a solve's device is chosen.

Without a GPU (CI, most machines) the kernels run under numba's CUDA
simulator. The simulator must be switched on (``NUMBA_ENABLE_CUDASIM=1``)
before numba-cuda is first imported, and it stays on for the life of the
process: so every CUDA solve here runs in a process of its own
(``tests/support/cuda_cases.py``), started with the variable set, and this
process, like every other test's, never sees it. With
``BEARCAT_CUDA_TESTS=hardware`` the same solves run on the GPU instead
(``benchmarks/device_checks.sh``), and the tests that need a machine
without one are skipped.

The sets must agree as the issue asks of a GPU backend: they may differ
only at nodes on the front (at most 0.01 % of the nodes, each next to the
zero level), which on grids this small means not at all; the values
themselves, the steps, the stopping window and T* agree to rounding.
"""

from __future__ import annotations

import importlib.util
import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bearcat.solvers.errors import InputError
from bearcat.solvers.levelset import devices
from bearcat.solvers.levelset.devices import Gpu, choose_device

ROOT = Path(__file__).resolve().parents[1]
HARDWARE = os.environ.get("BEARCAT_CUDA_TESTS") == "hardware"
FRONT_SHARE = 1e-4
"""Most nodes whose membership may differ, all on the front: 0.01 %."""
VALUE_TOL = {"float32": 1e-4, "float64": 1e-10}
"""Largest difference of the values, relative to the largest value."""

needs_numba_cuda = pytest.mark.skipif(
    importlib.util.find_spec("numba_cuda") is None, reason="numba-cuda is not installed (pip install 'bearcat[cuda]')"
)


def solved(case: str, scheme: str, tmp_path: Path, **options) -> tuple[dict, dict]:
    """``case`` solved on the CPU and under CUDA, in a fresh process whose
    numba-cuda runs in the simulator (or on the GPU, with ``HARDWARE``)."""
    out = tmp_path / f"{case}-{scheme}.npz"
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="0" if HARDWARE else "1")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
    command = [sys.executable, "-m", "tests.support.cuda_cases", str(out), case, scheme, json.dumps(options)]
    done = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    with np.load(out) as found:
        arrays = {key: found[key] for key in found.files if key != "meta"}
        return arrays, json.loads(str(found["meta"]))


def front(inside: np.ndarray) -> np.ndarray:
    """Nodes with a neighbour along some axis on the other side of the zero level."""
    near = np.zeros_like(inside)
    for axis in range(inside.ndim):
        a, n = np.moveaxis(inside, axis, 0), np.moveaxis(near, axis, 0)
        crossing = a[1:] != a[:-1]
        n[1:] |= crossing
        n[:-1] |= crossing
    return near


def assert_same_sets(cpu: np.ndarray, cuda: np.ndarray) -> None:
    """The sets differ at no more than 0.01 % of the nodes, each on the
    front; the values agree to rounding."""
    inside = cpu <= 0
    differ = inside != (cuda <= 0)
    assert differ.sum() <= FRONT_SHARE * cpu.size, f"{differ.sum()} of {cpu.size} nodes change side"
    assert not (differ & ~front(inside)).any(), "a node away from the front changes side"
    scale = float(np.abs(cpu).max())
    np.testing.assert_allclose(cuda, cpu, rtol=0, atol=VALUE_TOL[cpu.dtype.name] * scale)


def assert_same_tstar(cpu: np.ndarray, cuda: np.ndarray, cpu_value: np.ndarray, dt: float) -> None:
    """T* is finite at the same nodes but on the front, and equal to a
    hundredth of a step where both are."""
    differ = np.isfinite(cpu) != np.isfinite(cuda)
    assert not (differ & ~front(cpu_value <= 0)).any()
    both = np.isfinite(cpu) & np.isfinite(cuda)
    assert both.sum() > 0
    np.testing.assert_allclose(cuda[both], cpu[both], rtol=0, atol=0.01 * dt)


def assert_same_solve(arrays: dict, meta: dict) -> None:
    cpu, cuda = meta["cpu"], meta["cuda"]
    assert cuda["device"] != cpu["device"] and "CPU" in cpu["device"]
    assert ("simulator" in cuda["device"]) != HARDWARE
    for key in ("steps", "time", "converged_at", "node_updates"):
        assert cuda[key] == cpu[key], key
    assert_same_sets(arrays["cpu_value"], arrays["cuda_value"])
    if "cpu_tstar" in arrays:
        assert_same_tstar(arrays["cpu_tstar"], arrays["cuda_tstar"], arrays["cpu_value"], cpu["dt"])
    if "cpu_gradient" in arrays:
        g, h = arrays["cpu_gradient"], arrays["cuda_gradient"]
        both = np.isfinite(arrays["cpu_tstar"]) & np.isfinite(arrays["cuda_tstar"])
        np.testing.assert_allclose(h[both], g[both], rtol=0, atol=1e-3 * max(float(np.abs(g).max()), 1.0))


CASES = ["runner", "speed-map", "line-pursuit", "square-pursuit", "affine-ball", "affine-box"]


@needs_numba_cuda
@pytest.mark.parametrize("scheme", ["first", "weno5"])
@pytest.mark.parametrize("case", CASES)
def test_the_cuda_sets_are_the_cpu_sets(case, scheme, tmp_path):
    """Every Hamiltonian (simple motion with constant speeds and a speed map,
    a control against a disturbance, control-affine dynamics with balls and
    boxes), with and without an avoid set, on 2-D grids and a 4-D one whose
    every stencil reaches past an edge; T* and its gradient recorded."""
    arrays, meta = solved(case, scheme, tmp_path)
    assert meta["cpu"]["steps"] >= 2
    assert_same_solve(arrays, meta)
    inside = arrays["cpu_value"] <= 0
    assert 0 < inside.sum() < inside.size  # a front to compare


@needs_numba_cuda
@pytest.mark.parametrize("scheme", ["first", "weno5"])
def test_the_cuda_solve_stops_in_the_cpu_window(scheme, tmp_path):
    """Convergence by tolerance: the same window, so the same steps and set."""
    tol = {"first": 2e-3, "weno5": 1e-2}[scheme]  # WENO5 settles into a ripple of about 5e-3
    arrays, meta = solved("runner", scheme, tmp_path, horizon=6.0, tol=tol, check_every=0.25)
    assert meta["cpu"]["converged_at"] is not None and meta["cpu"]["converged_at"] < 6.0
    assert_same_solve(arrays, meta)


@needs_numba_cuda
def test_float64_without_the_monotone_clamp_or_the_gradient_on_cuda_is_the_cpu_solve(tmp_path):
    arrays, meta = solved(
        "line-pursuit", "weno5", tmp_path, dtype="float64", monotone=False, record_gradient=False, horizon=0.8
    )
    assert arrays["cpu_value"].dtype == np.float64 and "cpu_gradient" not in arrays
    assert_same_solve(arrays, meta)


@needs_numba_cuda
def test_the_two_stage_game_on_cuda_is_the_cpu_game(tmp_path):
    """``solve_ctf`` on device "cuda": R_A, then W_A from it, with T* and the
    fields built in place, as on the CPU."""
    arrays, meta = solved("ctf", "first", tmp_path)
    for name in ("return", "win"):
        cpu, cuda = meta["cpu"][name], meta["cuda"][name]
        assert (cuda["steps"], cuda["converged_at"]) == (cpu["steps"], cpu["converged_at"])
        assert ("simulator" in cuda["device"]) != HARDWARE
        value = arrays[f"cpu_{name}_value"]
        assert_same_sets(value, arrays[f"cuda_{name}_value"])
        assert_same_tstar(arrays[f"cpu_{name}_tstar"], arrays[f"cuda_{name}_tstar"], value, cpu["dt"])


# --- choosing the device ---


def no_gpu_here() -> bool:
    return isinstance(devices.find_gpu(), str)


def test_auto_takes_a_gpu_when_numba_cuda_finds_one_and_says_which(monkeypatch, caplog):
    monkeypatch.setattr(devices, "find_gpu", lambda: Gpu("NVIDIA H200"))
    with caplog.at_level(logging.INFO, logger="bearcat.solvers.levelset.devices"):
        chosen = choose_device("auto")
    assert chosen.kind == "cuda" and str(chosen) == "the GPU NVIDIA H200"
    assert "NVIDIA H200" in caplog.text
    assert choose_device("cpu").kind == "cpu"
    # Under the simulator "cuda" runs the kernels, but "auto" takes no simulator for a GPU.
    monkeypatch.setattr(devices, "find_gpu", lambda: Gpu("numba's CUDA simulator", simulated=True))
    assert choose_device("auto").kind == "cpu"
    assert choose_device("cuda").kind == "cuda"


def test_auto_takes_the_cpu_without_a_gpu_and_says_why(monkeypatch, caplog):
    monkeypatch.setattr(devices, "find_gpu", lambda: "numba-cuda finds no CUDA GPU or driver")
    with caplog.at_level(logging.INFO, logger="bearcat.solvers.levelset.devices"):
        chosen = choose_device("auto")
    assert chosen.kind == "cpu" and "finds no CUDA GPU" in caplog.text and "CPU" in caplog.text
    with pytest.raises(InputError, match=r"^device 'cuda' needs a CUDA GPU, but numba-cuda finds no CUDA GPU"):
        choose_device("cuda")
    with pytest.raises(InputError, match="device must be one of auto, cpu, cuda, got 'gpu'"):
        choose_device("gpu")


def tiny_problem():
    from bearcat.solvers.grid import Grid
    from bearcat.solvers.levelset.hamiltonians import Player, SimpleMotion

    grid = Grid.spanning((-1.0, -1.0), (1.0, 1.0), (11, 11))
    x, y = grid.mesh()
    return grid, SimpleMotion((Player((0, 1), 1.0),)), np.hypot(x, y) - 0.3


def test_the_narrow_band_runs_on_the_cpu(monkeypatch):
    from bearcat.solvers.levelset.hji import solve_reach_avoid

    monkeypatch.setattr(devices, "find_gpu", lambda: Gpu("NVIDIA H200"))
    grid, game, target = tiny_problem()
    refused = r"^device 'cuda' cannot solve this problem: the narrow band \(local\) runs on the CPU only; use device"
    with pytest.raises(InputError, match=refused):
        solve_reach_avoid(grid, game, target, horizon=0.2, local=True, device="cuda")
    found = solve_reach_avoid(grid, game, target, horizon=0.2, local=True, device="auto")
    assert "CPU" in found.device and found.local
    with pytest.raises(InputError, match="device must be one of auto, cpu, cuda, got 'CUDA'"):
        solve_reach_avoid(grid, game, target, horizon=0.2, device="CUDA")


@needs_numba_cuda
def test_problems_beyond_the_kernels_sizes_are_named():
    from bearcat.solvers.grid import Grid
    from bearcat.solvers.levelset import cuda as hji_cuda
    from bearcat.solvers.levelset.hamiltonians import Player, SimpleMotion, lower

    grid = Grid.spanning((0.0,) * 9, (1.0,) * 9, (2,) * 9)
    args = lower(SimpleMotion((Player(tuple(range(9)), 1.0),)), grid, np.float32).args
    assert hji_cuda.unsupported(9, args) == "the CUDA kernels take at most 8 dimensions, the grid has 9"
    assert hji_cuda.unsupported(8, args) is None


@pytest.mark.skipif(HARDWARE, reason="this machine has a GPU")
def test_cuda_without_a_gpu_is_one_sentence_and_exit_2(tmp_path, capsys, monkeypatch):
    """``bearcat solve ctf --device cuda`` on a machine without a GPU (or
    without numba-cuda): one sentence, exit code 2, nothing solved."""
    from bearcat.cli.main import main

    if not no_gpu_here():
        pytest.skip("this machine has a GPU")
    monkeypatch.setenv("BEARCAT_CACHE_DIR", str(tmp_path))
    code = main(["solve", "ctf", "--map", "ctf-10", "--grid", "9", "--capture-radius", "1.5", "--device", "cuda"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("bearcat: error: device 'cuda' needs a CUDA GPU, but "), err
    assert not list(tmp_path.rglob("*.npy"))


def test_the_cli_and_the_scenario_take_a_device(tmp_path):
    from bearcat.cli.main import build_parser
    from bearcat.scenarios.schema import ScenarioError, parse_scenario
    from tests.support.scenario_files import scenario_text

    args = build_parser("solve").parse_args(["solve", "ctf", "--map", "ctf-10", "--device", "cpu"])
    assert args.device == "cpu"
    assert build_parser("solve").parse_args(["solve", "maneuver", "backflip"]).device == "auto"
    text = scenario_text()
    assert parse_scenario(text, source="game.toml").rules.device == "auto"
    cuda = parse_scenario(text.replace("grid = 21", 'grid = 21\ndevice = "cuda"'), source="game.toml")
    assert cuda.rules.device == "cuda"
    with pytest.raises(ScenarioError, match=r"^game.toml: rules.device: 'gpu' is not one of 'auto', 'cpu', 'cuda'"):
        parse_scenario(text.replace("grid = 21", 'grid = 21\ndevice = "gpu"'), source="game.toml")


def test_the_cache_key_says_nothing_of_the_device():
    from bearcat.agents.ground_station.ctf_cache import CtfGame
    from bearcat.maps import load_map
    from bearcat.scenarios.cast import ctf_of
    from bearcat.scenarios.schema import parse_scenario
    from bearcat.solvers.ctf.sets import Rules
    from tests.support.scenario_files import scenario_text

    arena = load_map("ctf-10")
    games = [CtfGame(arena, 17, Rules(), device=device) for device in ("auto", "cpu", "cuda")]
    for name in ("return", "capture", "win"):
        assert len({game.set_key(name) for game in games}) == 1
    assert games[0] == games[2] and hash(games[0]) == hash(games[2])
    scenario = parse_scenario(scenario_text().replace("grid = 21", 'grid = 21\ndevice = "cpu"'), source="game.toml")
    assert ctf_of(scenario).own().device == "cpu"


@needs_numba_cuda
def test_the_shared_functions_are_those_the_cached_kernels_were_checked_against():
    """The CUDA kernels call functions of ``hji_kernels``, whose changes
    numba's cache of the kernels does not see: when this fails, check the
    kernels against the change and set ``hji_cuda.SHARED_SOURCE`` to the
    new hash (which, changing that file, retires the cached kernels)."""
    script = "from bearcat.solvers.levelset import cuda as h; print(h.shared_source(), h.SHARED_SOURCE)"
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1", PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
    now, recorded = done.stdout.split()
    assert now == recorded, f"set hji_cuda.SHARED_SOURCE to {now!r} once the kernels are checked"
