"""Where a player is now, from the fixes the network delivered: one tracker per player.

A fix is evidence, not a position (DESIGN.md, "Guidance under uncertainty").
Each ``Tracker`` estimates one player's position and velocity in map metres
together with the phone's GPS bias, and predicts them to the moment guidance
is computed.

- State, per mode: ``x = [east, north, v_east, v_north, b_east, b_north, c]``.
  The bias ``b`` is bearcat's own GPS error model (``netem.models.GpsError``):
  a first-order Gauss-Markov process of standard deviation ``bias_sigma`` and
  time constant ``tau``, plus white noise ``noise_sigma``. ``c`` is the
  compass's bias, drawn once per phone (``CompassError``): taken for white
  noise it would make the velocity disagree steadily with the fixes, a drift
  the GPS bias would be blamed for.
- A fix at ``t`` measures ``z = p + s b + s n``, where ``s`` is the fix's
  reported accuracy over the model's steady-state sigma (1 in the open, the
  urban factor near buildings: the phone scales bias and noise alike). Its
  compass reading measures the direction of motion ``atan2(v_east, v_north)``
  plus ``c`` when the player moves; standing still it says nothing and is left out.
- Two motion modes, mixed by an interacting multiple model (IMM): walking, a
  nearly constant velocity whose white acceleration is what a person's
  wandering heading gives (``walker.HEADING_TAU``, the scenario's heading
  error), and manoeuvring, whose acceleration reverses the top speed within a
  fix interval (a fake-out's feint). A Markov chain in continuous time moves
  between them. When the walking mode stops explaining the fixes its
  likelihood falls, the manoeuvre probability rises and the prediction widens
  at once; a few consistent fixes bring it back.
- Fixes are filtered at their own times. A late one (delivered after a newer
  one) is put in its place in a short buffer and the fixes after it are
  filtered again, so the estimate does not depend on the order of delivery.

Plain numpy over the two modes at once: a step is a few dozen small array
operations (benchmarks/tracker.py times it against Stone Soup's IMM).
"""

from __future__ import annotations

import bisect
import dataclasses
import logging
import math
from dataclasses import dataclass, field

import numpy as np

from bearcat.agents.human.walker import HEADING_TAU
from bearcat.bus.messages import Fix
from bearcat.maps import Map
from bearcat.netem.models import CompassError, GpsError

log = logging.getLogger(__name__)

TRACKER_ABLATIONS = ("prediction", "bias", "manoeuvre")
"""The parts of the trackers a study may switch off (``guidance.ablate``):
they change what the trackers estimate, and so what a calibration measures."""

WALKING, MANOEUVRING = 0, 1
MODES = ("walking", "manoeuvring")

POSITION, VELOCITY, BIAS, COMPASS = slice(0, 2), slice(2, 4), slice(4, 6), 6
SIZE = 7
KINEMATIC = slice(0, 4)


@dataclass(frozen=True)
class Motion:
    """The motion model of a tracker.

    ``walk`` and ``manoeuvre``: the white acceleration of each mode, m^2/s^3
    per axis. ``onset``: the rate (per second) of going from walking to
    manoeuvring; ``settle``: back. ``initial_speed``: the standard deviation
    per axis of the velocity before any fix tells it (m/s). ``compass_speed``:
    the speed under which the compass is not read (the player stands or the
    direction of motion is not known well enough to compare)."""

    walk: float
    manoeuvre: float
    onset: float = 0.1
    settle: float = 0.5
    initial_speed: float = 1.5
    compass_speed: float = 0.3

    @classmethod
    def of(cls, speed: float, heading_error: float = 10.0, fix_period: float = 1.0) -> Motion:
        """The model for a person of top ``speed`` (m/s) following a heading
        with ``heading_error`` degrees of wander (the scenario's, whose
        correlation time is the walker's ``HEADING_TAU``), reporting every
        ``fix_period`` seconds.

        Walking: a heading error of standard deviation ``sigma`` wandering with
        correlation time ``tau`` turns a velocity ``v`` by a cross-track
        velocity whose increments have the intensity ``2 v^2 sigma^2 / tau``.
        Manoeuvring: a reversal changes the velocity by ``2 v`` within a
        reaction time, so the velocity's standard deviation must grow by the
        top speed or more per fix interval: ``2 v^2 / period``."""
        sigma = math.radians(heading_error)
        walk = max(2.0 * speed**2 * sigma**2 / HEADING_TAU, 0.02)
        return cls(walk=walk, manoeuvre=2.0 * speed**2 / fix_period, initial_speed=max(speed / 2.0, 0.5))

    def walking_only(self) -> Motion:
        """This model without its manoeuvring mode: the walking mode is never
        left (an ablation: what the manoeuvre model gives)."""
        return dataclasses.replace(self, onset=0.0)


@dataclass(frozen=True)
class Belief:
    """A player as the tracker believes them at ``t``: the mixture of its modes
    and their moments.

    ``position`` and ``velocity`` (map metres, m/s) are the mixture's mean and
    ``covariance`` (4 x 4: east, north, v_east, v_north) its covariance;
    ``manoeuvre`` the probability that the player is manoeuvring; ``bias``
    and ``bias_covariance`` the phone's GPS bias (metres, unscaled). ``weights``,
    ``means`` (m x 4) and ``covariances`` (m x 4 x 4) are the modes'
    Gaussians, in ``MODES`` order, from which ``sample`` draws."""

    t: float
    position: np.ndarray
    velocity: np.ndarray
    covariance: np.ndarray
    manoeuvre: float
    bias: np.ndarray
    bias_covariance: np.ndarray
    weights: np.ndarray
    means: np.ndarray
    covariances: np.ndarray

    @property
    def position_covariance(self) -> np.ndarray:
        return self.covariance[POSITION, POSITION]

    def radius(self, confidence: float = 0.95) -> float:
        """The radius about ``position`` of a disk holding the player with
        probability ``confidence`` or more, taking the position as Gaussian
        with the mixture's covariance (its larger axis on both)."""
        largest = float(np.linalg.eigvalsh(self.position_covariance)[-1])
        return math.sqrt(-2.0 * math.log1p(-confidence) * max(largest, 0.0))

    def ellipse(self, confidence: float = 0.95) -> tuple[float, float, float]:
        """The ellipse holding the player with probability ``confidence``,
        the position taken as Gaussian with the mixture's covariance: its
        semi-major and semi-minor axes (metres) and the major axis's
        bearing (degrees clockwise from north, in [0, 180))."""
        scale = -2.0 * math.log1p(-confidence)
        eigenvalues, vectors = np.linalg.eigh(self.position_covariance)
        minor, major = (math.sqrt(scale * max(float(e), 0.0)) for e in eigenvalues)
        east, north = vectors[:, 1]
        return major, minor, math.degrees(math.atan2(east, north)) % 180.0

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` positions (n x 2, map metres) drawn from the mixture."""
        return self.draw(rng.standard_normal((n, 2)), rng.random(n))

    def draw(self, normals: np.ndarray, uniforms: np.ndarray) -> np.ndarray:
        """Positions from the mixture for given draws: ``uniforms`` (n) pick
        each one's mode by its weight, ``normals`` (n x 2, standard) place it
        in that mode's Gaussian. The same draws from one belief to the next
        (common random numbers) keep what is computed from the samples from
        jittering between guidance messages."""
        cumulative = np.cumsum(self.weights / self.weights.sum())
        modes = np.minimum(np.searchsorted(cumulative, uniforms, side="right"), len(self.weights) - 1)
        # Each mode's position covariance [[a, b], [b, c]] and its Cholesky root [[l00, 0], [l10, l11]].
        a = self.covariances[:, 0, 0] + 1e-12
        b = self.covariances[:, 0, 1]
        c = self.covariances[:, 1, 1] + 1e-12
        l00 = np.sqrt(a)
        l10 = b / l00
        l11 = np.sqrt(np.maximum(c - l10 * l10, 0.0))
        mean = self.means[modes, :2]
        east = mean[:, 0] + l00[modes] * normals[:, 0]
        north = mean[:, 1] + l10[modes] * normals[:, 0] + l11[modes] * normals[:, 1]
        return np.stack([east, north], axis=1)


@dataclass(frozen=True)
class _Observation:
    t: float
    seq: int
    z: np.ndarray  # measured position, map metres
    scale: float  # the fix's accuracy over the GPS model's sigma
    heading: float | None  # radians clockwise from north


@dataclass(frozen=True)
class _State:
    """The IMM's state after the fix at ``t``: mode probabilities (m), means (m x 6), covariances (m x 6 x 6)."""

    t: float
    mu: np.ndarray
    x: np.ndarray
    P: np.ndarray


@dataclass
class Tracker:
    """One player's tracker: GPS and compass error models (the profile's),
    and a ``Motion``. ``window`` seconds (and at most ``depth`` fixes) of
    fixes are kept to put a late one in its place; an older one is dropped."""

    gps: GpsError
    compass: CompassError
    motion: Motion
    window: float = 10.0
    depth: int = 32
    _fixes: list[_Observation] = field(default_factory=list, init=False, repr=False)
    _states: list[_State] = field(default_factory=list, init=False, repr=False)
    _base: _State | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        m = self.motion
        self._q = np.array([m.walk, m.manoeuvre])
        self._sigma = self.gps.horizontal_sigma()
        floor = math.radians(0.5) ** 2
        self._compass_bias = max(math.radians(self.compass.bias_sigma) ** 2, floor)
        self._compass_var = max(math.radians(self.compass.noise_sigma) ** 2, floor)

    # ------------------------------------------------------------ intake

    def take(self, fix: Fix, game_map: Map) -> bool:
        """Filter ``fix`` (a late one in its place); whether it was used (a
        duplicate, or one older than the buffer, is not)."""
        east, north = game_map.to_local(fix.lat, fix.lon)
        heading = None if fix.heading is None else math.radians(fix.heading)
        return self.observe(fix.t, (east, north), fix.accuracy, heading, seq=fix.seq)

    def observe(
        self, t: float, position, accuracy: float | None, heading: float | None = None, *, seq: int = 0
    ) -> bool:
        """Filter a fix taken at ``t`` of ``position`` (map metres) with the
        phone's ``accuracy`` (metres, 1 sigma; None: the model's) and compass
        ``heading`` (radians clockwise from north, or None)."""
        scale = 1.0
        if accuracy is not None and self._sigma > 0.0:
            scale = float(accuracy) / self._sigma
        obs = _Observation(float(t), int(seq), np.asarray(position, float).reshape(2), scale, heading)
        if self._base is not None and obs.t <= self._base.t:
            log.debug("fix at %.3f s is older than the buffer (from %.3f s): dropped", obs.t, self._base.t)
            return False
        times = [f.t for f in self._fixes]
        k = bisect.bisect_right(times, obs.t)
        if k > 0 and self._fixes[k - 1].t == obs.t:
            return False  # a duplicate
        self._fixes.insert(k, obs)
        del self._states[k:]
        state = self._states[k - 1] if k > 0 else self._base
        for f in self._fixes[k:]:
            state = self._initial(f) if state is None else self._step(state, f)
            self._states.append(state)
        self._trim()
        return True

    def _trim(self) -> None:
        latest = self._fixes[-1].t
        while len(self._fixes) > 1 and (len(self._fixes) > self.depth or self._fixes[0].t < latest - self.window):
            self._fixes.pop(0)
            self._base = self._states.pop(0)

    # ------------------------------------------------------------ output

    @property
    def latest(self) -> float | None:
        """Time of the newest fix filtered (None before the first)."""
        return self._states[-1].t if self._states else None

    def predict(self, now: float) -> Belief | None:
        """The belief at ``now`` (at the newest fix if ``now`` is before it);
        None before the first fix. Nothing changes in the tracker."""
        if not self._states:
            return None
        state = self._states[-1]
        dt = max(float(now) - state.t, 0.0)
        mu, x, P = self._predict(state, dt)
        return _belief(state.t + dt, mu, x, P)

    # ------------------------------------------------------------ filter

    def _initial(self, f: _Observation) -> _State:
        """The state after a first fix: the position is the fix less the bias
        and noise the model gives it, the velocity its prior."""
        g, s = self.gps, f.scale
        x = np.zeros(SIZE)
        x[POSITION] = f.z
        P = np.zeros((SIZE, SIZE))
        eye = np.eye(2)
        P[POSITION, POSITION] = s * s * (g.bias_sigma**2 + g.noise_sigma**2) * eye + _FLOOR * eye
        P[POSITION, BIAS] = P[BIAS, POSITION] = -s * g.bias_sigma**2 * eye
        P[BIAS, BIAS] = g.bias_sigma**2 * eye
        P[VELOCITY, VELOCITY] = self.motion.initial_speed**2 * eye
        P[COMPASS, COMPASS] = self._compass_bias
        mu = self._stationary()
        n = len(mu)
        return _State(f.t, mu, np.repeat(x[None], n, axis=0), np.repeat(P[None], n, axis=0))

    def _stationary(self) -> np.ndarray:
        m = self.motion
        r = m.onset + m.settle
        return np.array([m.settle / r, m.onset / r]) if r > 0 else np.array([1.0, 0.0])

    def _transition(self, dt: float) -> np.ndarray:
        """Mode transition probabilities over ``dt`` (row: from, column: to)."""
        m = self.motion
        r = m.onset + m.settle
        if r <= 0:
            return np.eye(2)
        e = -math.expm1(-r * dt)
        a, b = m.onset / r * e, m.settle / r * e
        return np.array([[1.0 - a, a], [b, 1.0 - b]])

    def _predict(self, state: _State, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Mix the modes over ``dt`` and predict each: (mode probabilities, means, covariances)."""
        T = self._transition(dt)
        c = state.mu @ T  # predicted mode probabilities
        w = state.mu[:, None] * T / np.maximum(c, 1e-300)[None, :]  # w[i, j] = P(was i | now j)
        x0 = w.T @ state.x
        d = state.x[None, :, :] - x0[:, None, :]  # [j, i, :]
        wd = w.T[:, :, None] * d
        P0 = (w.T @ state.P.reshape(len(c), -1)).reshape(state.P.shape) + np.swapaxes(wd, 1, 2) @ d
        F, Q = self._model(dt)
        x = x0 @ F.T
        P = F @ P0 @ F.T + Q
        return c, x, P

    def _model(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """The transition matrix and each mode's process noise over ``dt``."""
        g = self.gps
        F = np.eye(SIZE)
        F[0, 2] = F[1, 3] = dt
        F[4, 4] = F[5, 5] = math.exp(-dt / g.tau)
        kinematic = dt**3 / 3.0 * _PP + dt**2 / 2.0 * _PV + dt * _VV
        Q = self._q[:, None, None] * kinematic + g.bias_sigma**2 * -math.expm1(-2.0 * dt / g.tau) * _BB
        return F, Q

    def _step(self, state: _State, f: _Observation) -> _State:
        """Predict the state to the fix and update it with the fix's position and compass."""
        c, x, P = self._predict(state, f.t - state.t)
        g, s = self.gps, f.scale
        # Position: z = p + s b + s n.
        r = s * s * g.noise_sigma**2 + _FLOOR
        nu = f.z[None, :] - x[:, POSITION] - s * x[:, BIAS]  # (m, 2)
        PH = P[:, :, POSITION] + s * P[:, :, BIAS]  # P H^T, (m, n, 2)
        S = PH[:, POSITION, :] + s * PH[:, BIAS, :]  # H P H^T, (m, 2, 2)
        a, b, d = S[:, 0, 0] + r, S[:, 0, 1], S[:, 1, 1] + r
        det = a * d - b * b
        Si = np.stack([np.stack([d, -b], axis=-1), np.stack([-b, a], axis=-1)], axis=-2) / det[:, None, None]
        K = PH @ Si
        x = x + (K @ nu[:, :, None])[:, :, 0]
        P = P - K @ np.swapaxes(PH, 1, 2)
        maha = (nu[:, None, :] @ Si @ nu[:, :, None])[:, 0, 0]
        loglik = -0.5 * maha - 0.5 * np.log(det) - math.log(2.0 * math.pi)
        if f.heading is not None:
            x, P, more = self._compass(c, x, P, f.heading)
            loglik = loglik + more
        post = np.log(np.maximum(c, 1e-300)) + loglik
        post = np.exp(post - post.max())
        mu = post / post.sum()
        P = 0.5 * (P + np.swapaxes(P, 1, 2))
        return _State(f.t, mu, x, P)

    def _compass(self, c, x, P, heading: float):
        """Update each mode with a compass ``heading`` (radians) as a
        measurement of the direction of motion, if the player moves; the
        modes' log-likelihoods of it (0 when it is not read).

        The reading is used only if the mixture's speed is above
        ``compass_speed`` and twice its own standard deviation (a standing
        player's phone repeats its last heading). Its likelihood is a
        Gaussian in the angle mixed with a uniform 5 % (a reversal makes the
        reading a half turn off, where the linearisation means nothing): every
        mode is scored on it, and only a mode it fits within three sigma is
        moved by it."""
        v = c @ x[:, VELOCITY]
        Pv = np.einsum("m,mab->ab", c, P[:, VELOCITY, VELOCITY])
        speed = math.hypot(v[0], v[1])
        if speed < max(self.motion.compass_speed, 2.0 * math.sqrt(max(np.trace(Pv), 0.0) / 2.0)):
            return x, P, 0.0
        x, P = x.copy(), P.copy()
        loglik = np.zeros(len(c))
        for j in range(len(c)):
            vx, vy = x[j, 2], x[j, 3]
            r2 = vx * vx + vy * vy
            if r2 < 1e-12:
                loglik[j] = math.log(_OUTLIER / (2.0 * math.pi))
                continue
            h = np.zeros(SIZE)
            h[2], h[3], h[COMPASS] = vy / r2, -vx / r2, 1.0
            nu = (heading - math.atan2(vx, vy) - x[j, COMPASS] + math.pi) % (2.0 * math.pi) - math.pi
            Ph = P[j] @ h
            S = float(h @ Ph) + self._compass_var
            gauss = math.exp(-0.5 * nu * nu / S) / math.sqrt(2.0 * math.pi * S)
            loglik[j] = math.log((1.0 - _OUTLIER) * gauss + _OUTLIER / (2.0 * math.pi))
            if nu * nu <= 9.0 * S:
                K = Ph / S
                x[j] = x[j] + K * nu
                P[j] = P[j] - np.outer(K, Ph)
        return x, P, loglik


def _template(*pairs: tuple[int, int]) -> np.ndarray:
    out = np.zeros((SIZE, SIZE))
    for i, j in pairs:
        out[i, j] = out[j, i] = 1.0
    return out


_PP, _PV, _VV, _BB = (
    _template((0, 0), (1, 1)),
    _template((0, 2), (1, 3)),
    _template((2, 2), (3, 3)),
    _template((4, 4), (5, 5)),
)
_FLOOR = 1e-6  # m^2: the least measurement variance, so an exact fix keeps the filter well posed
_OUTLIER = 0.05  # the share of compass readings taken to say nothing of the motion


def _belief(t: float, mu: np.ndarray, x: np.ndarray, P: np.ndarray) -> Belief:
    means = x[:, KINEMATIC]
    covs = P[:, KINEMATIC, KINEMATIC]
    mean, cov = _moments(mu, means, covs)
    bias, bias_cov = _moments(mu, x[:, BIAS], P[:, BIAS, BIAS])
    return Belief(
        t=t,
        position=mean[POSITION].copy(),
        velocity=mean[VELOCITY].copy(),
        covariance=cov,
        manoeuvre=float(mu[MANOEUVRING]),
        bias=bias,
        bias_covariance=bias_cov,
        weights=mu.copy(),
        means=means.copy(),
        covariances=covs.copy(),
    )


def _moments(mu: np.ndarray, means: np.ndarray, covs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of the Gaussian mixture of weights ``mu``."""
    mean = mu @ means
    d = means - mean
    return mean, np.einsum("m,mab->ab", mu, covs) + np.einsum("m,ma,mb->ab", mu, d, d)


class Trackers:
    """A tracker per player on ``game_map``: each fix to its player's, every
    player predicted to one moment. ``motions`` gives a player's ``Motion``
    (others get ``default``). ``to_now=False`` leaves each belief at its
    player's latest fix instead (an ablation: what predicting to now gives)."""

    def __init__(
        self,
        game_map: Map,
        gps: GpsError,
        compass: CompassError,
        *,
        motions: dict[str, Motion] | None = None,
        default: Motion | None = None,
        to_now: bool = True,
    ) -> None:
        self.map = game_map
        self.gps = gps
        self.compass = compass
        self.motions = dict(motions or {})
        self.default = default or Motion.of(3.0)
        self.to_now = to_now
        self.trackers: dict[str, Tracker] = {}

    def take(self, fix: Fix) -> bool:
        """Give ``fix`` to its player's tracker; whether it was used."""
        tracker = self.trackers.get(fix.agent)
        if tracker is None:
            motion = self.motions.get(fix.agent, self.default)
            tracker = self.trackers[fix.agent] = Tracker(self.gps, self.compass, motion)
        return tracker.take(fix, self.map)

    def predict(self, now: float) -> dict[str, Belief]:
        """Every player with a fix, as believed at ``now``."""
        out = {}
        for agent, tracker in self.trackers.items():
            belief = tracker.predict(now if self.to_now else -math.inf)
            if belief is not None:
                out[agent] = belief
        return out
