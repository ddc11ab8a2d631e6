"""Geometry of the safety filter: the boxes the robot's envelope must stay in, and the envelope.

The keep-in boxes of config/iss.yaml touch face to face at every hatch, so no single keep-in box
holds a robot crossing a hatch. The filter therefore chooses, per envelope point, one box out of
a set of *corridor boxes*: the keep-in boxes (grown by the filter's margin) plus every chain of
them merged along one axis (astrobee.station.merged_chains: the chain's span along that axis
times the intersection of their cross-sections). Each merged box lies inside the union of its chain, so keeping a point inside
any one candidate box keeps it inside the union; a long corridor (Node 2 -> hatch -> JEM) is one
box, which is what lets the filter stay transparent while the robot flies through a hatch.

Boxes are arrays [xmin, ymin, zmin, xmax, ymax, zmax] in the world frame.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from astrobee import config
from astrobee.station import drop_contained, grow, merged_chains, robot_radius

from ..clearance import CUBE

CHAIN_ROUNDS = 4    # chains of up to five keep-in boxes
MIN_CROSS = 0.3     # m: the narrowest cross-section a merged corridor keeps


@dataclass(frozen=True)
class BodySphere:
    """A sphere fixed to the robot: centre at `offset` (m, BODY frame, from the robot point) and
    `radius` (m; 0 for a point such as a box corner)."""

    offset: np.ndarray
    radius: float


def robot_sphere(radius: float | None = None) -> BodySphere:
    """The robot's envelope as one sphere (default radius: astrobee.station.robot_radius)."""
    return BodySphere(np.zeros(3), robot_radius() if radius is None else float(radius))


def box_corners(centre_offset: np.ndarray, size: np.ndarray,
                rotation_body: np.ndarray | None = None) -> list[BodySphere]:
    """The 8 corners of a carried box (e.g. a cargo bag) as zero-radius body points: a box lies
    in a convex box exactly when its corners do. `rotation_body` (3x3) turns the box's own axes
    into the robot body frame."""
    c = np.asarray(centre_offset, float)
    half = 0.5 * np.asarray(size, float)
    r = np.eye(3) if rotation_body is None else np.asarray(rotation_body, float)
    return [BodySphere(c + r @ (s * half), 0.0) for s in CUBE]


def box_sphere(centre_offset: np.ndarray, size: np.ndarray) -> BodySphere:
    """A carried box as its circumscribed sphere (one point instead of eight; conservative)."""
    return BodySphere(np.asarray(centre_offset, float),
                      float(0.5 * np.linalg.norm(np.asarray(size, float))))


def corridor_boxes(keep_in: np.ndarray | None = None, margin: float = 0.0) -> np.ndarray:
    """Candidate boxes for the filter: keep-in boxes grown by `margin` plus their merged chains,
    boxes inside another dropped. Default: the station's keep-in set (cached)."""
    if keep_in is None:
        return _station_corridors(float(margin)).copy()
    return _corridors(grow(keep_in, margin))


@lru_cache(maxsize=8)
def _station_corridors(margin: float) -> np.ndarray:
    return _corridors(grow(config.keep_in_boxes(), margin))


def _corridors(grown: np.ndarray) -> np.ndarray:
    return drop_contained(np.vstack([grown, merged_chains(grown, CHAIN_ROUNDS, MIN_CROSS)]))
