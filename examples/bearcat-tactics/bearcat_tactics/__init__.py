"""Tactics of one's own for bearcat, registered under its entry-point groups."""
