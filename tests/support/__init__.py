"""Helpers shared by the test modules: scenario files and the like."""
