"""Zenoh sessions, key expressions, message types and codec, clocks, and the in-process bus."""
