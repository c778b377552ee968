"""RouteTracker: a route polyline and how far along it a position is."""

from __future__ import annotations

import numpy as np

from drivelab.world.state import Route

SEARCH_WINDOW_M = 60.0  # after the first projection, look no farther than this from the last one
WINDOW_PENALTY_M = 1e3  # a point outside the window counts this much farther than it is
CLOSED_GAP_M = 5.0  # a polyline whose ends are this close is a circuit


class RouteTracker:
    """Projects positions on a route polyline.

    :param polyline: (K, 2) points; repeated points are dropped.
    :param has_goal: the route ends at a destination (else its length is reported as infinite).
    """

    def __init__(self, polyline: np.ndarray, has_goal: bool) -> None:
        keep = np.r_[True, np.linalg.norm(np.diff(polyline, axis=0), axis=1) > 1e-6]
        self.polyline = polyline[keep]
        self.stations = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(self.polyline, axis=0), axis=1))]
        self.closed = bool(np.linalg.norm(self.polyline[-1] - self.polyline[0]) < CLOSED_GAP_M)
        self.length_m = float(self.stations[-1]) if has_goal else float("inf")
        self._starts = self.polyline[:-1]
        self._segments = self.polyline[1:] - self._starts
        self._lengths2 = np.maximum((self._segments**2).sum(axis=1), 1e-12)

    def project(self, position: np.ndarray, previous_m: float | None = None) -> float:
        """Arc length along the route of the point nearest ``position``.

        With ``previous_m`` the search stays within 60 m of it (a circuit passes near itself), and
        on a circuit the result is unwrapped so that it keeps growing lap after lap.
        """
        t = np.clip(((position - self._starts) * self._segments).sum(axis=1) / self._lengths2, 0.0, 1.0)
        distance = np.linalg.norm(self._starts + t[:, None] * self._segments - position, axis=1)
        station = self.stations[:-1] + t * np.sqrt(self._lengths2)
        if previous_m is None:
            return float(station[int(np.argmin(distance))])
        gap = station - previous_m
        if self.closed:
            lap_m = self.stations[-1]
            gap = (gap + lap_m / 2) % lap_m - lap_m / 2
        distance = distance + WINDOW_PENALTY_M * (np.abs(gap) > SEARCH_WINDOW_M)
        return float(previous_m + gap[int(np.argmin(distance))])

    def at(self, progress_m: float) -> Route:
        """The WorldState's Route at ``progress_m``."""
        return Route(self.polyline, progress_m, self.length_m, self.stations, self.closed)
