"""Time one predict + update of the ground station's opponent tracker
(agents/ground_station/tracker.py) against Stone Soup's Kalman filter doing
the same linear work.

    python benchmarks/tracker.py            # 2000 fixes each
    python benchmarks/tracker.py --fixes 500

Stone Soup (in the ``bench`` extra) ships no interacting multiple model,
so its side is the IMM's filtering alone: for each of the two modes a
``KalmanPredictor`` and a ``KalmanUpdater`` over the same six-state model
(position, velocity and a Gauss-Markov GPS bias, as custom linear Gaussian
models) and the same position measurement ``z = p + b``. Its mixing, mode
probabilities and compass are left out, which favours it. bearcat's
tracker is timed on the same fixes twice: with the compass (its own full
step) and without. Without Stone Soup only bearcat's times are printed.
"""

from __future__ import annotations

import argparse
import math
import time
from datetime import datetime, timedelta

import numpy as np

from bearcat.agents.ground_station.tracker import Motion, Tracker
from bearcat.netem.profiles import load_profile


def fixes(n: int, seed: int = 0):
    """``n`` fixes a second apart of a walk at 2 m/s turning slowly: (t, position, heading)."""
    rng = np.random.default_rng(seed)
    gps = load_profile("wifi").gps
    t = np.arange(n, dtype=float)
    bearing = 0.3 * np.sin(t / 20.0)
    truth = np.cumsum(2.0 * np.stack([np.sin(bearing), np.cos(bearing)], axis=1), axis=0)
    z = truth + rng.normal(0.0, gps.horizontal_sigma(), size=truth.shape)
    return [(float(t[k]), z[k], float(bearing[k])) for k in range(n)]


def time_bearcat(data, compass: bool) -> float:
    p = load_profile("wifi")
    tracker = Tracker(p.gps, p.compass, Motion.of(2.0))
    accuracy = p.gps.horizontal_sigma()
    for t, z, h in data[:10]:  # warm up
        tracker.observe(t - 100.0, z, accuracy, h if compass else None)
    tracker = Tracker(p.gps, p.compass, Motion.of(2.0))
    start = time.perf_counter()
    for t, z, h in data:
        tracker.observe(t, z, accuracy, h if compass else None)
    return (time.perf_counter() - start) / len(data)


def time_stonesoup(data) -> float | None:
    try:
        from stonesoup.base import Property
        from stonesoup.models.measurement.linear import LinearGaussian
        from stonesoup.models.transition.linear import LinearGaussianTransitionModel
        from stonesoup.predictor.kalman import KalmanPredictor
        from stonesoup.types.detection import Detection
        from stonesoup.types.hypothesis import SingleHypothesis
        from stonesoup.types.state import GaussianState
        from stonesoup.updater.kalman import KalmanUpdater
    except ImportError:
        return None

    gps = load_profile("wifi").gps
    motion = Motion.of(2.0)

    class Walk(LinearGaussianTransitionModel):
        """Constant velocity per axis with white acceleration ``q``, and a Gauss-Markov bias."""

        q: float = Property(doc="white acceleration, m^2/s^3")

        @property
        def ndim_state(self):
            return 6

        def matrix(self, time_interval=timedelta(seconds=1), **kwargs):
            dt = time_interval.total_seconds()
            F = np.eye(6)
            F[0, 2] = F[1, 3] = dt
            F[4, 4] = F[5, 5] = math.exp(-dt / gps.tau)
            return F

        def covar(self, time_interval=timedelta(seconds=1), **kwargs):
            dt = time_interval.total_seconds()
            Q = np.zeros((6, 6))
            for a in (0, 1):
                Q[a, a] = self.q * dt**3 / 3.0
                Q[a, 2 + a] = Q[2 + a, a] = self.q * dt**2 / 2.0
                Q[2 + a, 2 + a] = self.q * dt
                Q[4 + a, 4 + a] = gps.bias_sigma**2 * -math.expm1(-2.0 * dt / gps.tau)
            return Q

    class Fix(LinearGaussian):
        """Position plus bias."""

        def matrix(self, **kwargs):
            H = np.zeros((2, 6))
            H[0, 0] = H[1, 1] = H[0, 4] = H[1, 5] = 1.0
            return H

    measurement = Fix(ndim_state=6, mapping=(0, 1), noise_covar=np.eye(2) * gps.noise_sigma**2)
    filters = [(KalmanPredictor(Walk(q=q)), KalmanUpdater(measurement)) for q in (motion.walk, motion.manoeuvre)]
    epoch = datetime(2024, 1, 1)
    P = np.diag([4.0, 4.0, 2.0, 2.0, gps.bias_sigma**2, gps.bias_sigma**2])
    states = [GaussianState(np.zeros((6, 1)), P, timestamp=epoch) for _ in filters]
    start = time.perf_counter()
    for t, z, _ in data:
        when = epoch + timedelta(seconds=t + 1.0)
        detection = Detection(z.reshape(2, 1), timestamp=when, measurement_model=measurement)
        for j, (predictor, updater) in enumerate(filters):
            prediction = predictor.predict(states[j], timestamp=when)
            states[j] = updater.update(SingleHypothesis(prediction, detection))
    return (time.perf_counter() - start) / len(data)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fixes", type=int, default=2000)
    args = parser.parse_args()
    data = fixes(args.fixes)
    ours = time_bearcat(data, compass=True)
    plain = time_bearcat(data, compass=False)
    print(f"bearcat tracker, IMM of 2 modes, fix + compass: {ours * 1e6:8.1f} us per predict + update")
    print(f"bearcat tracker, IMM of 2 modes, fix only:      {plain * 1e6:8.1f} us per predict + update")
    theirs = time_stonesoup(data)
    if theirs is None:
        print("Stone Soup is not installed (pip install stonesoup): no comparison")
        return
    print(f"Stone Soup, 2 Kalman filters (no mixing):       {theirs * 1e6:8.1f} us per predict + update")
    print(f"ratio Stone Soup / bearcat: {theirs / plain:.1f} (fix only), {theirs / ours:.1f} (bearcat with compass)")


if __name__ == "__main__":
    main()
