"""Scenario files (TOML), their schema and loader, and the runners: simulate
and launch for one scenario (to come), ``batch`` for many independent
trials, ``pursuit_experiment`` for the comparison trials of thesis 5.3.2."""
