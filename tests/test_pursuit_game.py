"""The closed-loop pursuit referee: capture within a step, blocked moves,
and a chase whose capture time is known in closed form."""

import numpy as np
import pytest

from bearcat.solvers.errors import InputError
from bearcat.solvers.pursuit.game import first_contact, pursue


def test_agents_that_pass_through_each_other_within_one_step_are_caught():
    # Head-on, 3 apart, each moving 2 in the step: at the step's ends they
    # are 3 and 1 apart, beyond a 0.5 capture radius, but they meet midway.
    s = first_contact((0.0, 0.0), (2.0, 0.0), (3.0, 0.0), (1.0, 0.0), 0.5)
    assert s == pytest.approx((3.0 - 0.5) / 4.0)
    assert first_contact((0.0, 0.0), (2.0, 0.0), (3.0, 1.0), (1.0, 1.0), 0.5) is None  # a metre apart sideways
    assert first_contact((0.0, 0.0), (1.0, 0.0), (0.3, 0.0), (5.0, 0.0), 0.5) == 0.0  # already within
    assert first_contact((0.0, 0.0), (1.0, 0.0), (9.0, 0.0), (8.0, 0.0), 0.5) is None  # closing, not yet


class Toward:
    def headings(self, evader, pursuers):
        d = evader - pursuers
        return d / np.linalg.norm(d, axis=1, keepdims=True)


class Away:
    def __init__(self, direction):
        self.direction = np.asarray(direction, float)

    def heading(self, evader, pursuers):
        return self.direction


def open_field(point):
    return bool(np.all((np.asarray(point) >= 0) & (np.asarray(point) <= 10)))


def test_a_faster_pursuer_catches_a_fleeing_evader_when_the_gap_closes_to_the_radius():
    # Gap 4, closing at 2 - 1 = 1 per unit time: capture at (4 - 0.5) / 1 = 3.5,
    # whatever the step, since contact is found inside the step.
    for dt in (0.01, 0.3, 0.7):
        chase = pursue(
            Toward(),
            Away((1.0, 0.0)),
            (5.0, 5.0),
            [(1.0, 5.0)],
            passable=open_field,
            dt=dt,
            capture_radius=0.5,
            pursuer_speeds=2.0,
        )
        assert chase.captured and chase.captor == 0
        assert chase.capture_time == pytest.approx(3.5, abs=1e-9)
        assert np.hypot(*(chase.evader[-1] - chase.pursuers[-1, 0])) == pytest.approx(0.5)


def test_walls_stop_the_evader_and_the_chase_ends_there():
    # The evader runs into the east wall at x = 10 after 2 units and stops;
    # an equally fast pursuer 4 behind then closes at 1: capture at 2 + 3.5.
    chase = pursue(Toward(), Away((1.0, 0.0)), (8.0, 5.0), [(4.0, 5.0)], passable=open_field, dt=0.05)
    assert chase.captured and chase.capture_time == pytest.approx(5.5, abs=0.06)
    assert chase.evader[:, 0].max() <= 10.0


def test_an_evader_that_keeps_its_distance_is_never_caught_and_the_clock_stops_at_the_limit():
    chase = pursue(Toward(), Away((0.0, 1.0)), (5.0, 1.0), [(5.0, -3.0)], passable=lambda p: True, dt=0.1, max_time=4.0)
    assert not chase.captured and chase.times[-1] == pytest.approx(4.0)
    assert np.allclose(np.hypot(*(chase.evader - chase.pursuers[:, 0]).T), 4.0)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(dt=0.0), "dt must be a positive finite number"),
        (dict(max_time=float("inf")), "max_time must be a positive finite number"),
        (dict(capture_radius=-0.5), "capture radius must be a finite number >= 0"),
    ],
)
def test_bad_numbers_are_named(change, message):
    with pytest.raises(InputError, match=message):
        pursue(Toward(), Away((1, 0)), (5, 5), [(1, 5)], passable=open_field, **change)


def test_bad_starts_and_bad_headings_are_named():
    with pytest.raises(InputError, match="pursuer 1 starts at"):
        pursue(Toward(), Away((1, 0)), (5, 5), [(11, 5)], passable=open_field)

    class Broken:
        def headings(self, evader, pursuers):
            return np.zeros((3, 2))

    with pytest.raises(InputError, match="shape"):
        pursue(Broken(), Away((1, 0)), (5, 5), [(1, 5)], passable=open_field)
