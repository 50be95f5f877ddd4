"""The margin calibrated guidance adds to its value: measured, not assumed.

Calibrated guidance answers at where the trackers predict the players are
(``guidance.ctf``). What the trackers cannot know, it pays for with a margin:
the score of one answer is the error in the value itself,

    s = V(true state) - V(state the guidance used),

collected on simulated games (``bearcat calibrate``) and binned by the game's
phase and by the reports' age (the older of the two players' latest fixes,
the one thing the guidance knows that the error grows with). Per bin the
margin is the split-conformal quantile of the scores at ``1 - alpha``: the
``ceil((n + 1)(1 - alpha))``-th smallest of ``n``. An attacker's go then
holds only when ``V_hat + margin < 0``, so for an answer drawn like the
calibration's, the true value is below zero, and the go right, with
probability at least ``1 - alpha`` (Angelopoulos and Bates, 2023; for a
planner's margin, Lindemann et al., RA-L 2023). A bin with fewer than
``1 / alpha - 1`` scores cannot bound that quantile, and gives no margin:
no go is said at such ages.

Scores of one game are not independent (the answers are ten a second): a
bin whose scores come from fewer than ``MIN_GAMES`` games gives no margin
either, whatever their number, and the held-out check (``coverage``)
resamples whole games for its interval.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["AGE_EDGES", "MIN_GAMES", "Calibration", "Coverage", "Score", "conformal_quantile", "coverage", "fit"]

AGE_EDGES = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, math.inf)
"""Bins of report age (s): as fine as a fix period where most answers are,
and doubling where ages come only from losses and outages."""
MIN_GAMES = 10
"""Games a bin's scores must come from before its quantile is taken for the error's."""
PHASES = ("capture", "return")
FORMAT = 1


@dataclass(frozen=True)
class Score:
    """One answer of a calibration game: when (``t``, game time), in which
    ``phase``, the reports' ``age``, the value the guidance used and the
    value at the true state."""

    game: int
    t: float
    phase: str
    age: float
    estimated: float
    true: float

    @property
    def error(self) -> float:
        return self.true - self.estimated


@dataclass(frozen=True)
class Calibration:
    """Per phase and age bin (``edges``), the margin at ``alpha`` (None:
    too few scores to bound it) and how many scores it came from; ``about``
    says what it was calibrated for and on which games."""

    alpha: float
    edges: tuple[float, ...]
    margins: dict[str, tuple[float | None, ...]]
    counts: dict[str, tuple[int, ...]]
    about: dict = field(default_factory=dict)

    def bin(self, age: float) -> int:
        """The bin of ``age`` (a negative age, a clock ahead of the fix, is the first)."""
        k = int(np.searchsorted(self.edges, max(age, 0.0), side="right")) - 1
        return min(max(k, 0), len(self.edges) - 2)

    def margin(self, phase: str, age: float) -> float | None:
        """The margin for an answer in ``phase`` from reports ``age`` seconds
        old; None where the calibration cannot bound the error."""
        margins = self.margins.get(phase)
        return None if margins is None else margins[self.bin(age)]

    def to_json(self) -> dict:
        edges = [None if math.isinf(e) else e for e in self.edges]
        return {
            "format": FORMAT,
            "alpha": self.alpha,
            "edges": edges,
            "margins": {p: list(m) for p, m in self.margins.items()},
            "counts": {p: list(c) for p, c in self.counts.items()},
            "about": self.about,
        }

    @classmethod
    def from_json(cls, data: dict) -> Calibration:
        """The calibration ``to_json`` wrote; ValueError for anything else."""
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise ValueError(f"not a calibration of format {FORMAT}")
        edges = tuple(math.inf if e is None else float(e) for e in data["edges"])
        bins = len(edges) - 1
        margins = {p: tuple(None if m is None else float(m) for m in ms) for p, ms in data["margins"].items()}
        counts = {p: tuple(int(c) for c in cs) for p, cs in data["counts"].items()}
        if bins < 1 or any(len(m) != bins for m in (*margins.values(), *counts.values())):
            raise ValueError("a calibration's margins and counts must have one entry per age bin")
        return cls(float(data["alpha"]), edges, margins, counts, dict(data.get("about") or {}))


def conformal_quantile(errors: np.ndarray, alpha: float) -> float | None:
    """The split-conformal ``1 - alpha`` quantile of ``errors``: the
    ``ceil((n + 1)(1 - alpha))``-th smallest, or None if that rank exceeds ``n``."""
    n = len(errors)
    rank = math.ceil((n + 1) * (1.0 - alpha))
    if rank > n:
        return None
    return float(np.partition(np.asarray(errors, float), rank - 1)[rank - 1])


def fit(scores: Sequence[Score], alpha: float, edges=AGE_EDGES, about: dict | None = None) -> Calibration:
    """The calibration of ``scores`` at ``alpha``."""
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"alpha must lie between 0 and 1, got {alpha!r}")
    empty = Calibration(alpha, tuple(edges), {}, {})
    margins, counts = {}, {}
    for phase in PHASES:
        ours = [s for s in scores if s.phase == phase]
        if not ours:
            continue
        bins = np.array([empty.bin(s.age) for s in ours])
        errors = np.array([s.error for s in ours])
        games = np.array([s.game for s in ours])
        per_bin = [bins == k for k in range(len(edges) - 1)]
        margins[phase] = tuple(
            conformal_quantile(errors[b], alpha) if len(set(games[b])) >= MIN_GAMES else None for b in per_bin
        )
        counts[phase] = tuple(int(b.sum()) for b in per_bin)
    return Calibration(alpha, tuple(edges), margins, counts, dict(about or {}))


@dataclass(frozen=True)
class Coverage:
    """How often held-out scores of one bin lay within the margin:
    ``covered`` of ``scores`` from ``games`` games, and the share; its 95 %
    interval comes from resampling whole games, those the margin was fitted
    on (the margin is fitted again each time) and the held-out ones, so it
    holds what a calibration of this many games delivers. ``verdict``:
    ``"holds"`` where that interval holds the promised ``1 - alpha``,
    ``"conservative"`` where it lies above (the margin is wider than it need
    be), ``"short"`` where it lies below (goes are wrong more often than
    promised), None where the bin had no margin or no scores."""

    phase: str
    ages: tuple[float, float]
    margin: float | None
    scores: int
    games: int
    covered: int
    share: float | None
    interval: tuple[float, float] | None
    verdict: str | None


def coverage(
    calibration: Calibration,
    fitted: Sequence[Score],
    scores: Sequence[Score],
    *,
    resamples: int = 1000,
    seed: int = 0,
) -> list[Coverage]:
    """Per phase and bin of ``calibration`` (made from the scores ``fitted``),
    its coverage on ``scores``, which it must not have seen."""
    rng = np.random.default_rng(seed)
    out = []
    edges = calibration.edges
    target = 1.0 - calibration.alpha
    for phase, margins in calibration.margins.items():
        for k, margin in enumerate(margins):
            ages = (edges[k], edges[k + 1])
            held = _by_game(s for s in scores if s.phase == phase and calibration.bin(s.age) == k)
            n = sum(len(e) for e in held)
            if margin is None or not held:
                out.append(Coverage(phase, ages, margin, n, len(held), 0, None, None, None))
                continue
            fit_games = _by_game(s for s in fitted if s.phase == phase and calibration.bin(s.age) == k)
            covered = sum(int((e <= margin).sum()) for e in held)
            shares = []
            for _ in range(resamples):
                refit = conformal_quantile(
                    np.concatenate([fit_games[i] for i in _draw(rng, len(fit_games))]), calibration.alpha
                )
                if refit is None:
                    continue
                drawn = [held[i] for i in _draw(rng, len(held))]
                shares.append(sum(int((e <= refit).sum()) for e in drawn) / sum(len(e) for e in drawn))
            low, high = (float(x) for x in np.quantile(shares, [0.025, 0.975]))
            verdict = "short" if high < target else "conservative" if low > target else "holds"
            out.append(Coverage(phase, ages, margin, n, len(held), covered, covered / n, (low, high), verdict))
    return out


def _by_game(scores) -> list[np.ndarray]:
    """The errors of ``scores``, one array per game."""
    games: dict[int, list[float]] = {}
    for s in scores:
        games.setdefault(s.game, []).append(s.error)
    return [np.array(e) for e in games.values()]


def _draw(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.integers(0, n, size=n)
