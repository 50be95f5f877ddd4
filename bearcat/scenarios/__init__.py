"""Scenario files (TOML): the typed schema and loader, variants of a
scenario, the cast of agents it builds, maneuvers, and fault plans with
their effects."""
