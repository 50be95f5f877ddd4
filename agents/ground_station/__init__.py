"""Guidance service, referee, UAV tasking and recorder."""
