"""bearcat: field simulator for reachability-guided adversarial games (command-line interface)."""

__version__ = "0.1.0"
