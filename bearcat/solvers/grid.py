"""The Cartesian grid every solver and raster shares.

Arrays laid on a grid are indexed ``[i0, i1, ...]`` with axis ``k`` along
state dimension ``k`` (``indexing="ij"``): for a map, ``array[ix, iy]`` with
``x`` east and ``y`` north, both in metres. Keeping one convention everywhere
means a value function, a speed raster and a mask can be combined without
transposes, and plots transpose once at the edge.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Grid:
    """Nodes ``lo[k] + i * spacing[k]`` for ``i`` in ``range(shape[k])``."""

    lo: tuple[float, ...]
    spacing: tuple[float, ...]
    shape: tuple[int, ...]

    def __post_init__(self) -> None:
        if not (len(self.lo) == len(self.spacing) == len(self.shape)):
            raise ValueError("grid lo, spacing and shape must have one entry per dimension")
        if any(not math.isfinite(v) for v in self.lo):
            raise ValueError(f"grid origin must be finite, got {self.lo}")
        if any(not (h > 0 and math.isfinite(h)) for h in self.spacing):
            raise ValueError(f"grid spacing must be positive and finite, got {self.spacing}")
        if any(n < 2 for n in self.shape):
            raise ValueError(f"a grid needs at least two nodes per axis, got shape {self.shape}")

    @classmethod
    def covering(cls, lo, hi, spacing: float) -> Grid:
        """The grid of uniform ``spacing`` whose first node is ``lo`` and whose
        last node is the first at or beyond ``hi``, so the box is fully sampled."""
        lo = tuple(float(v) for v in lo)
        hi = tuple(float(v) for v in hi)
        spacing = float(spacing)
        if not (spacing > 0 and math.isfinite(spacing)):
            raise ValueError(f"grid spacing must be positive and finite, got {spacing}")
        # The small tolerance keeps a box that is an exact multiple of the
        # spacing from gaining a spurious extra node through rounding.
        shape = tuple(int(math.ceil((b - a) / spacing - 1e-9)) + 1 for a, b in zip(lo, hi))
        return cls(lo, (spacing,) * len(lo), shape)

    @classmethod
    def spanning(cls, lo, hi, shape) -> Grid:
        """The grid with ``shape`` nodes per axis, first node on ``lo`` and last on ``hi``."""
        lo = tuple(float(v) for v in lo)
        hi = tuple(float(v) for v in hi)
        shape = tuple(int(n) for n in shape)
        spacing = tuple((b - a) / (n - 1) if n > 1 else 0.0 for a, b, n in zip(lo, hi, shape))
        return cls(lo, spacing, shape)

    @property
    def ndim(self) -> int:
        return len(self.shape)

    @property
    def size(self) -> int:
        return math.prod(self.shape)

    @property
    def hi(self) -> tuple[float, ...]:
        """Coordinates of the last node along each axis."""
        return tuple(a + (n - 1) * h for a, h, n in zip(self.lo, self.spacing, self.shape))

    @property
    def cell_area(self) -> float:
        """Measure of one cell (area in 2-D), for turning node counts into areas."""
        return math.prod(self.spacing)

    def axes(self) -> tuple[np.ndarray, ...]:
        return tuple(a + h * np.arange(n) for a, h, n in zip(self.lo, self.spacing, self.shape))

    def mesh(self) -> tuple[np.ndarray, ...]:
        return tuple(np.meshgrid(*self.axes(), indexing="ij"))

    def contains(self, point) -> bool:
        """Whether ``point`` (one point) lies within the box spanned by the nodes."""
        coords = [float(v) for v in np.ravel(point)]
        if len(coords) != self.ndim:
            raise ValueError(f"a point on a {self.ndim}-D grid has {self.ndim} coordinates, got {len(coords)}")
        return all(a - 1e-9 <= c <= b + 1e-9 for c, a, b in zip(coords, self.lo, self._hi))

    @functools.cached_property
    def _hi(self) -> tuple[float, ...]:
        return self.hi

    def fractional_index(self, points) -> np.ndarray:
        """Continuous node coordinates of ``points`` (shape ``(..., ndim)``)."""
        p = np.asarray(points, dtype=float)
        return (p - np.asarray(self.lo)) / np.asarray(self.spacing)

    def nearest_index(self, point) -> tuple[int, ...]:
        """The node closest to ``point``, clipped into the grid."""
        k = np.rint(self.fractional_index(point)).astype(int)
        return tuple(min(max(int(v), 0), n - 1) for v, n in zip(k, self.shape))

    def point(self, index) -> np.ndarray:
        """Coordinates of the node at ``index``."""
        return np.asarray(self.lo) + np.asarray(index, dtype=float) * np.asarray(self.spacing)
