"""Cooperative pursuit (thesis 5): safe-reachable-area pursuit in convex domains (convex), among obstacles
(fmm), and games of it played out (game)."""
