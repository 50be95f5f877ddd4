"""The progress bars: a log file gets a few redraws of a long solve, not one per step, and the last one is whole."""

from bearcat.cli.progress import counting, solve_bars


def test_a_solve_logged_to_a_file_is_redrawn_rarely_and_ends_at_its_horizon(capsys):
    """Under pytest stderr is not a terminal, as when a batch job logs to a
    file: 400 solver steps within a second must not leave 400 redraws."""
    progress = solve_bars(label=lambda name: f"solving {name}")
    steps = 400
    for name in ("return", "capture"):
        for k in range(1, steps + 1):
            progress(name, 60.0 * k / steps, 60.0, 1.0 / k)
    progress.close()
    err = capsys.readouterr().err
    draws = [d for d in err.replace("\n", "\r").split("\r") if d.startswith("solving")]
    assert 2 <= len(draws) <= 6, draws
    last = {name: [d for d in draws if d.startswith(f"solving {name}")][-1] for name in ("return", "capture")}
    for line in last.values():
        assert "100%" in line and "60.00/60.00 s of game time" in line
        assert f"change {1.0 / steps:.3g} m" in line


def test_a_batch_logged_to_a_file_counts_every_task(capsys):
    with counting(250, "games", "game") as finished:
        for _ in range(250):
            finished("result")
    draws = [d for d in capsys.readouterr().err.replace("\n", "\r").split("\r") if d.startswith("games")]
    assert len(draws) <= 3, draws
    assert "250/250" in draws[-1]
