"""Impairment models, pure and seeded: every draw comes from a
``numpy.random.Generator`` the caller owns, so a link or a sensor replays
exactly for a seed.

Link models follow Linux ``tc netem`` where it has the same knob (delay with
jitter and a distribution, Bernoulli and Gilbert-Elliott loss, duplication,
reordering, rate), plus what a cellular link adds: outages in time windows,
no signal in map regions, and the radio's promotion delay for the first
packet after it went idle (HSPA: 1-2.6 s). Sensor models: GPS error as a
first-order Gauss-Markov (Ornstein-Uhlenbeck) bias plus white noise, larger
near buildings, with dropouts; compass error as a per-run bias plus noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Annotated, Literal, get_args

import msgspec
import numpy as np
from msgspec import Meta

Distribution = Literal["constant", "uniform", "normal", "pareto", "lognormal"]
DISTRIBUTIONS: tuple[Distribution, ...] = get_args(Distribution)

# Bounds of the models a profile file gives as tables (netem/profiles.py reads them).
Probability = Annotated[float, Meta(ge=0.0, le=1.0, description="a probability in [0, 1]")]
Metres = Annotated[float, Meta(ge=0.0, le=1000.0, extra={"unit": "m"})]
ErrorDegrees = Annotated[float, Meta(ge=0.0, le=180.0, extra={"unit": "degrees"})]


class _Table(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """A model given as a TOML table: its keys are exactly the fields."""


@dataclass(frozen=True)
class Delay:
    """One-way delay ``base`` plus a ``jitter`` of the given ``distribution``
    (its standard deviation; the half-width for ``uniform``; for ``pareto``
    and ``lognormal`` the jitter is one-sided with that standard deviation,
    the heavy tail of cellular links). Never below zero."""

    base: float = 0.0
    jitter: float = 0.0
    distribution: Distribution = "normal"

    @property
    def mean(self) -> float:
        """The mean delay (the clipping of normal jitter at zero aside)."""
        extra = {"pareto": 1.0 / math.sqrt(3.0), "lognormal": 1.0 / math.sqrt(math.e - 1.0)}
        return self.base + self.jitter * extra.get(self.distribution, 0.0)

    def sample(self, rng: np.random.Generator) -> float:
        """One delay drawn on its own."""
        return self.at(float(rng.standard_normal()))

    def at(self, score: float) -> float:
        """The delay whose quantile is that of the standard normal ``score``:
        a link whose scores move slowly (``LinkState``) gives close packets
        close delays, with this distribution for each of them."""
        j = self.jitter
        if j == 0.0 or self.distribution == "constant":
            return self.base
        if self.distribution == "normal":
            extra = j * score
        elif self.distribution == "uniform":
            extra = j * (1.0 - math.erfc(score / math.sqrt(2.0)))  # 2 Phi(score) - 1 of the half-width
        elif self.distribution == "pareto":
            # Lomax with shape 3 scaled to standard deviation j (mean j / sqrt 3), from its survival.
            survival = 0.5 * math.erfc(score / math.sqrt(2.0))
            extra = (2.0 * j / math.sqrt(3.0)) * (max(survival, 1e-300) ** (-1.0 / 3.0) - 1.0)
        else:  # lognormal with sigma 1 scaled to standard deviation j (mean j / sqrt(e - 1) ~ 0.76 j)
            extra = j / math.sqrt((math.e - 1.0) * math.e) * math.exp(score)
        return max(0.0, self.base + extra)


class GilbertElliott(_Table, frozen=True):
    """Two-state burst loss: a good state losing ``loss_good`` of packets and
    a bad one losing ``loss_bad``; each packet moves good -> bad with ``p``
    and bad -> good with ``r`` (``tc netem loss gemodel p r 1-h 1-k``).
    Mean burst length ``1 / r``; stationary loss
    ``(r loss_good + p loss_bad) / (p + r)``."""

    p: Probability
    r: Probability
    loss_good: Probability = 0.0
    loss_bad: Probability = 1.0

    @property
    def stationary_loss(self) -> float:
        if self.p + self.r == 0.0:
            return self.loss_good
        return (self.r * self.loss_good + self.p * self.loss_bad) / (self.p + self.r)


@dataclass(frozen=True)
class Outage:
    """No link at all from ``start`` to ``end`` (seconds of game time)."""

    start: float
    end: float

    def covers(self, t: float) -> bool:
        return self.start <= t < self.end


@dataclass(frozen=True)
class LinkModel:
    """Everything that happens to a message on one directed link.

    ``loss`` is Bernoulli, ``burst`` Gilbert-Elliott (both may apply);
    ``duplicate`` the chance of a second copy (its own delay draw);
    ``jitter_time`` how long the delay's jitter takes to change (its
    correlation time: packets sent close together get close delays, as on
    a cellular link whose delay is mostly queueing; 0 draws each packet's
    alone);
    ``reorder`` the chance a packet skips the delay's base (netem's
    reordering: it overtakes those still in flight); ``rate`` in
    bytes per second serialises messages (0: unlimited); ``idle_after``
    seconds without traffic demote the radio, and the next message waits a
    promotion delay drawn uniformly from ``promotion``; ``outages`` are time
    windows without signal. How a TCP stream
    recovers what the link loses follows from the delays (``netem.link.Tcp``)."""

    delay: Delay = field(default_factory=Delay)
    jitter_time: float = 0.0
    loss: float = 0.0
    burst: GilbertElliott | None = None
    duplicate: float = 0.0
    reorder: float = 0.0
    rate: float = 0.0
    idle_after: float = 0.0
    promotion: tuple[float, float] = (0.0, 0.0)
    outages: tuple[Outage, ...] = ()

    @property
    def ideal(self) -> bool:
        return self == LinkModel()


class GpsError(_Table, frozen=True):
    """Phone GPS error in metres (east, north).

    A bias per axis following a first-order Gauss-Markov process with
    standard deviation ``bias_sigma`` and correlation time ``tau`` (seconds),
    plus white noise ``noise_sigma``; both scale by ``urban_factor`` within
    ``urban_distance`` of a building (multipath, blocked sky). A fix is not
    produced with probability ``dropout`` (``urban_dropout`` near buildings)."""

    bias_sigma: Metres = 0.0
    tau: Annotated[float, Meta(gt=0.0, le=86400.0, extra={"unit": "s"})] = 60.0
    noise_sigma: Metres = 0.0
    urban_factor: Annotated[float, Meta(ge=0.0, le=100.0)] = 1.0
    urban_distance: Metres = 0.0
    dropout: Probability = 0.0
    urban_dropout: Probability = 0.0

    def horizontal_sigma(self, urban: bool = False) -> float:
        """Standard deviation of the error per axis at steady state."""
        s = math.hypot(self.bias_sigma, self.noise_sigma)
        return s * (self.urban_factor if urban else 1.0)

    def as_white(self) -> GpsError:
        """The same error taken for white noise of the same size: no bias,
        the noise its steady-state sigma (what a filter without a bias state assumes)."""
        return msgspec.structs.replace(self, bias_sigma=0.0, noise_sigma=self.horizontal_sigma())


class CompassError(_Table, frozen=True):
    """Phone compass error in degrees: a bias drawn once per phone and white noise."""

    bias_sigma: ErrorDegrees = 0.0
    noise_sigma: ErrorDegrees = 0.0


class GpsTrack:
    """The error one phone's GPS makes, fix after fix (stateful: the bias)."""

    def __init__(self, model: GpsError, rng: np.random.Generator) -> None:
        self.model = model
        self.rng = rng
        self.bias = rng.normal(0.0, model.bias_sigma, size=2) if model.bias_sigma > 0 else np.zeros(2)
        self._t: float | None = None

    def error(self, t: float, distance_to_building: float = math.inf) -> np.ndarray | None:
        """The (east, north) error of a fix taken at ``t``, or None for a dropout."""
        m = self.model
        urban = distance_to_building <= m.urban_distance
        scale = m.urban_factor if urban else 1.0
        if self._t is not None and m.bias_sigma > 0:
            # Exact discretisation of the OU process over the elapsed time.
            a = math.exp(-max(t - self._t, 0.0) / m.tau)
            self.bias = a * self.bias + m.bias_sigma * math.sqrt(1.0 - a * a) * self.rng.normal(size=2)
        self._t = t
        noise = self.rng.normal(0.0, m.noise_sigma, size=2) if m.noise_sigma > 0 else np.zeros(2)
        if self.rng.random() < (m.urban_dropout if urban else m.dropout):
            return None
        return scale * (self.bias + noise)


class CompassTrack:
    """One phone's compass: heading in, heading as the phone reports it out (radians)."""

    def __init__(self, model: CompassError, rng: np.random.Generator) -> None:
        self.model = model
        self.rng = rng
        self.bias = math.radians(rng.normal(0.0, model.bias_sigma)) if model.bias_sigma > 0 else 0.0

    def reading(self, heading: float) -> float:
        noise = math.radians(self.rng.normal(0.0, self.model.noise_sigma)) if self.model.noise_sigma > 0 else 0.0
        return (heading + self.bias + noise) % (2.0 * math.pi)
