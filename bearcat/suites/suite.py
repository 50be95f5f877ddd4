"""Fault-injection suites: cases of a scenario, a fault plan and seeds, each
run and judged by the run checker.

A suite is a TOML file::

    [suite]
    name = "mine"

    [[case]]
    name = "defender-killed"
    scenario = "fake-out"            # a built-in name, or a file beside the suite
    seeds = 2                        # how many (from the scenario's seed), or a list
    set = { "scenario.time_limit" = 30.0, "scenario.lease" = 3.0 }   # scenario variants
    expect = ["verdict", "detection"]   # invariants that must hold (default: every one that applies)
    [[case.fault]]
    kind = "kill"
    target = "defender"
    at = 5.0

Each case and seed runs in ``OUT/CASE/seed-S`` (simulated or live), the
checker reads that directory, and the case passes if every invariant it
expects held (one that does not apply to the run counts as held only if the
case did not name it). A case's faults may also come from a plan file
(``faults = "plan.toml"``).
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Annotated

import msgspec
from msgspec import Meta

from bearcat.bus.messages import Name
from bearcat.runtime.run_directory import write_scenario
from bearcat.scenarios.faults import Fault, FaultError, check_faults, load_faults, refusal, write_faults
from bearcat.scenarios.schema import Scenario, ScenarioError, list_scenarios, load_scenario
from bearcat.scenarios.variants import vary
from bearcat.suites.checker import INVARIANTS, Run, check_run, detected_after
from bearcat.validation import Invalid, convert

RUNTIMES = ("simulate", "live")


class CaseTable(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    name: Name
    scenario: Annotated[str, Meta(min_length=1)]
    seeds: Annotated[int, Meta(ge=1, le=10_000)] | tuple[Annotated[int, Meta(ge=0)], ...] = 1
    set: dict[str, object] = {}
    expect: tuple[str, ...] = ()
    fault: tuple[Fault, ...] = ()
    faults: str | None = None
    netem: str | None = None


class SuiteHead(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    name: Name
    description: str = ""


class SuiteFile(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    suite: SuiteHead
    case: Annotated[tuple[CaseTable, ...], Meta(min_length=1)]


@dataclass(frozen=True)
class Case:
    """One case, ready to run: its scenario (with the variants applied), plan and seeds."""

    name: str
    scenario: Scenario
    faults: tuple
    seeds: tuple[int, ...]
    expect: tuple[str, ...]
    netem: str | None


@dataclass
class CaseResult:
    case: str
    seed: int
    faults: str
    detected: str
    outcome: str
    held: list[str] = field(default_factory=list)
    broken: list[str] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)  # expected, but not applicable to the run
    run: str = ""
    evidence: dict[str, str] = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return not self.broken and not self.missing


def builtin_suite() -> Path:
    from importlib import resources

    return Path(str(resources.files("bearcat.scenarios") / "data" / "suites" / "builtin.toml"))


def load_suite(path: str | Path) -> tuple[str, list[Case]]:
    """The suite's name and its cases, each checked (a bad one is one sentence naming it)."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FaultError(f"there is no suite {str(path)!r}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError, OSError) as exc:
        raise FaultError(f"{path} cannot be read as a suite: {exc}") from None
    try:
        suite = convert(data, SuiteFile)
    except Invalid as exc:
        raise FaultError(f"{path}: {exc}") from None
    cases = []
    for k, table in enumerate(suite.case):
        where = f"{path}: case[{k}] ({table.name})"
        ref = table.scenario
        if ref not in list_scenarios() and not Path(ref).is_absolute():
            ref = str(path.parent / ref)
        try:
            scenario = vary(load_scenario(ref), dict(table.set))
            faults = table.fault
            if table.faults is not None:
                faults = (*faults, *load_faults(path.parent / table.faults, scenario))
            check_faults(faults, scenario.agents, scenario.uavs, scenario.committing)
        except (ScenarioError, FaultError) as exc:
            raise FaultError(f"{where}: {exc}") from None
        except Invalid as exc:
            raise FaultError(f"{where}: {exc}") from None
        unknown = [name for name in table.expect if name not in INVARIANTS]
        if unknown:
            raise FaultError(f"{where}: expect: {unknown[0]!r} is not an invariant; they are {', '.join(INVARIANTS)}")
        seeds = (
            tuple(table.seeds)
            if isinstance(table.seeds, tuple)
            else tuple(range(scenario.seed, scenario.seed + table.seeds))
        )
        cases.append(Case(table.name, scenario, tuple(faults), seeds, tuple(table.expect), table.netem))
    names = [c.name for c in cases]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise FaultError(f"{path}: case name {twice[0]!r} is used twice")
    return suite.suite.name, cases


def refusals(cases: list[Case], runtime: str) -> str | None:
    """The first case the runtime cannot run, in one sentence, or None."""
    for case in cases:
        why = refusal(case.faults, runtime)
        if why is not None:
            return f"case {case.name}: {why}"
    return None


def run_case(case: Case, seed: int, out: Path, *, runtime: str, network: str = "shim", say=print) -> CaseResult:
    """Run one case for one seed into ``out`` and judge it."""
    out.mkdir(parents=True)
    write_scenario(out, case.scenario)
    if case.faults:
        write_faults(out / "faults.toml", case.faults)
    outcome = _simulate(case, seed, out) if runtime == "simulate" else _live(case, seed, out, network, say)
    run = Run(out)
    findings = {f.name: f for f in check_run(run)}
    expected = case.expect or tuple(name for name, f in findings.items() if f.held is not None)
    result = CaseResult(
        case=case.name,
        seed=seed,
        faults="; ".join(f.describe() for f in case.faults) or "none",
        detected=", ".join(f"{s:.2f} s" for s in detected_after(run).values()) or "-",
        outcome=outcome,
        run=str(out),
        evidence={name: f.evidence for name, f in findings.items()},
    )
    for name in expected:
        held = findings[name].held
        (result.held if held else result.broken if held is False else result.missing).append(name)
    return result


def _simulate(case: Case, seed: int, out: Path) -> str:
    from bearcat.agents.ground_station.rerun_recording import finish_run
    from bearcat.runtime.simulate import simulate

    outcome = simulate(case.scenario, seed=seed, netem=case.netem, events=out / "events.jsonl", faults=case.faults)
    (out / "outcome.json").write_text(json.dumps(asdict(outcome), indent=2) + "\n")
    finish_run(out, case.scenario)
    return _said(outcome.winner, outcome.reason)


def _live(case: Case, seed: int, out: Path, network: str, say) -> str:
    from bearcat.runtime.launch import launch

    outcome = launch(
        case.scenario,
        str((out / "scenario.toml").resolve()),
        out,
        seed=seed,
        netem=case.netem or case.scenario.netem,
        network=network,
        say=lambda text: None,
        faults=case.faults,
    )
    return _said(outcome.winner, outcome.reason)


def _said(winner: str | None, reason: str) -> str:
    return f"{winner} wins: {reason}" if winner else reason


def table(results: list[CaseResult]) -> str:
    """The suite's table: case, fault, detected after, outcome, invariants held."""
    rows = [("case", "seed", "fault", "detected after", "outcome", "invariants")]
    for r in results:
        verdict = f"{len(r.held)}/{len(r.held) + len(r.broken) + len(r.missing)} held"
        if r.broken:
            verdict += f"; BROKEN: {', '.join(r.broken)}"
        if r.missing:
            verdict += f"; did not apply: {', '.join(r.missing)}"
        rows.append((r.case, str(r.seed), r.faults, r.detected, r.outcome, verdict))
    widths = [min(max(len(row[j]) for row in rows), 48) for j in range(len(rows[0]))]
    lines = []
    for row in rows:
        cells = [cell if len(cell) <= w else cell[: w - 1] + "…" for cell, w in zip(row, widths, strict=True)]
        lines.append("  ".join(cell.ljust(w) for cell, w in zip(cells, widths, strict=True)).rstrip())
    return "\n".join(lines)
