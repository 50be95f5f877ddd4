"""A pytest plugin for fault-injection suites of one's own.

Installed with bearcat (its ``pytest11`` entry point), it gives every test
session three fixtures:

- ``bearcat_simulate(scenario, faults=(), seed=None, **changes)``: play a
  scenario in virtual time under a fault plan into a fresh run directory;
- ``bearcat_live(scenario, faults=(), seed=None, network="shim", **changes)``:
  play it live, every peer its own process, the faults applied by the launcher;
- ``bearcat_check(run)``: the run checker's findings for a run directory.

``scenario`` is a built-in name, a file or a ``Scenario``; ``faults`` a plan
file or a list of fault tables (``{"kind": "kill", "target": "defender",
"at": 5.0}``); ``changes`` set scenario keys by their dotted path, with
``__`` for the dots (``scenario__lease=3.0``, ``rules__grid=21``). Each
returns a ``Run``: its directory, its outcome and the checker's findings,
with ``run.held("detection")`` and ``run.assert_held()`` to assert on::

    def test_my_walker_rejoins(bearcat_simulate):
        run = bearcat_simulate("fake-out", [{"kind": "restart", "target": "attacker", "at": 3.0}])
        run.assert_held()
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import pytest


@dataclass
class Run:
    """A run directory with its outcome and the checker's findings by invariant."""

    directory: Path
    outcome: dict
    findings: dict

    def held(self, invariant: str) -> bool | None:
        """Whether ``invariant`` held (None: it does not apply to this run)."""
        return self.findings[invariant].held

    def assert_held(self, *invariants: str) -> None:
        """Fail the test unless every named invariant (default: every one that applies) held."""
        names = invariants or [n for n, f in self.findings.items() if f.held is not None]
        broken = [f"{n}: {self.findings[n].evidence}" for n in names if self.findings[n].held is not True]
        if broken:
            pytest.fail(f"invariants of {self.directory} did not hold: " + "; ".join(broken), pytrace=False)


def _prepare(scenario, faults, changes):
    from bearcat.scenarios.faults import check_faults, load_faults, parse_faults
    from bearcat.scenarios.schema import Scenario, load_scenario
    from bearcat.scenarios.variants import vary

    if not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario)
    scenario = vary(scenario, {k.replace("__", "."): v for k, v in changes.items()})
    if isinstance(faults, str | Path):
        plan = load_faults(faults, scenario)
    else:
        plan = parse_faults(list(faults))
        check_faults(plan, scenario.agents, scenario.uavs, scenario.committing)
    return scenario, plan


def _judged(directory: Path) -> Run:
    from bearcat.suites.checker import check_run

    outcome = json.loads((directory / "outcome.json").read_text())
    return Run(directory, outcome, {f.name: f for f in check_run(directory)})


@pytest.fixture
def bearcat_simulate(tmp_path_factory):
    """Play a scenario in virtual time under a fault plan; a judged ``Run``."""
    from bearcat.runtime.run_directory import write_scenario
    from bearcat.runtime.simulate import simulate

    def play(scenario, faults=(), seed=None, **changes) -> Run:
        scenario, plan = _prepare(scenario, faults, changes)
        directory = tmp_path_factory.mktemp("bearcat-run")
        write_scenario(directory, scenario)
        outcome = simulate(scenario, seed=seed, faults=plan, events=directory / "events.jsonl")
        (directory / "outcome.json").write_text(json.dumps(asdict(outcome), indent=2) + "\n")
        return _judged(directory)

    return play


@pytest.fixture
def bearcat_live(tmp_path_factory):
    """Play a scenario live, every peer its own process, under a fault plan; a judged ``Run``."""
    from bearcat.runtime.launch import launch
    from bearcat.runtime.run_directory import write_scenario
    from bearcat.runtime.solve_ahead import solve_ahead

    def play(scenario, faults=(), seed=None, network="shim", **changes) -> Run:
        scenario, plan = _prepare(scenario, faults, changes)
        directory = tmp_path_factory.mktemp("bearcat-run")
        write_scenario(directory, scenario)
        solve_ahead(scenario, scenario.netem)
        launch(
            scenario,
            str((directory / "scenario.toml").resolve()),
            directory,
            seed=scenario.seed if seed is None else seed,
            netem=scenario.netem,
            network=network,
            say=lambda text: None,
            faults=plan,
        )
        return _judged(directory)

    return play


@pytest.fixture
def bearcat_check():
    """The checker's findings for a run directory, as a judged ``Run``."""
    return lambda directory: _judged(Path(directory))
