"""Fault-injection suites, the run checker that judges a run directory, and
the pytest plugin that plays scenarios under fault plans."""
