"""Reachability-designed maneuvers (thesis 6.1): capture, avoid and forward-reach sets of a sequence of
modes, the planar quadrotor, and the backflip designed and flown."""
