"""Matplotlib figures of games, studies and maneuvers, and screenshots of Rerun recordings."""
