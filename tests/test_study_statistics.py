"""The study tables' statistics, against published values."""

import pytest

from bearcat.studies.thesis import summarise_search, wilson


@pytest.mark.parametrize(
    "successes, trials, low, high",
    # Newcombe (1998), Statistics in Medicine 17:857, Table I, method 3 (Wilson score).
    [(81, 263, 0.2553, 0.3662), (15, 148, 0.0624, 0.1605), (0, 20, 0.0, 0.1611), (1, 29, 0.0061, 0.1718)],
)
def test_the_wilson_interval_matches_newcombes_table(successes, trials, low, high):
    assert wilson(successes, trials) == pytest.approx((low, high), abs=5e-5)


def test_search_rows_give_median_mean_and_interval_of_the_games_that_found_the_defender():
    games = [
        {"search": "lawnmower", "winner": w, "found_at": t}
        for w, t in [("attacker", 30.0), ("defender", 10.0), ("defender", None), ("attacker", 21.0), ("x", 12.5)]
    ]
    (row,) = summarise_search(games)
    assert (row["games"], row["found"], row["attacker_wins"]) == (5, 4, 2)
    assert row["median_time_to_find"] == 16.75 and row["mean_time_to_find"] == 18.38
    assert row["win_rate_95"] == [round(v, 3) for v in wilson(2, 5)] == [0.118, 0.769]
