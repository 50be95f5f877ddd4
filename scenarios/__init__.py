"""Scenario files (TOML), their schema and loader, and the simulate and launch runners."""
