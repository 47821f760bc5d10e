"""Oriented bounding boxes: overlap, TTC at constant velocities, time headway.

A box is ``[x, y, psi, length, width]``: centre (m), heading (rad, counter-clockwise from
+x), size along and across the heading (m).

Touching convention: two boxes collide only when their intersection has positive area.
Boxes that share an edge or a corner (zero-area contact) do not overlap; in floating point,
an axis separates when |d · u| ≥ r_A(u) + r_B(u).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riskcore import kernels as _kernels
from riskcore.errors import RiskcoreError

__all__ = ["boxes_overlap", "time_headway", "ttc_constant_velocity"]

FloatArray = NDArray[np.float64]


def _boxes(boxes: ArrayLike, name: str) -> FloatArray:
    arr = np.asarray(boxes, dtype=np.float64)
    if arr.ndim < 1 or arr.shape[-1] != 5:
        raise RiskcoreError(f"{name}: expected shape (..., 5) = [x, y, psi, length, width], "
                         f"got {arr.shape}")
    if not np.isfinite(arr).all():
        raise RiskcoreError(f"{name}: values must be finite")
    if (arr[..., 3:] <= 0).any():
        raise RiskcoreError(f"{name}: length and width must be > 0")
    return arr


def boxes_overlap(boxes_a: ArrayLike, boxes_b: ArrayLike) -> NDArray[np.bool_]:
    """Separating-axis overlap test of pairs of oriented boxes.

    Parameters
    ----------
    boxes_a, boxes_b : array-like of shape (..., 5)
        ``[x, y, psi, length, width]``; broadcast against each other.

    Returns
    -------
    ndarray of bool of the broadcast shape (...)
        True where the two boxes overlap with positive area (touching is False).
    """
    a = _boxes(boxes_a, "boxes_a")
    b = _boxes(boxes_b, "boxes_b")
    a, b = np.broadcast_arrays(a, b)
    shape = a.shape[:-1]
    res = _kernels.overlap_many(np.ascontiguousarray(a.reshape(-1, 5)),
                                np.ascontiguousarray(b.reshape(-1, 5)))
    return np.asarray(res.reshape(shape), dtype=np.bool_)


def ttc_constant_velocity(box_a: ArrayLike, v_a: ArrayLike, box_b: ArrayLike,
                          v_b: ArrayLike) -> FloatArray:
    """Time to collision of two boxes moving at constant velocity along their headings.

    Exact for the boxes: with fixed orientations, the projections of the relative position
    on each of the four box axes move linearly in time, so each axis gives an open time
    interval of overlap; the boxes overlap on the intersection of the four. TTC is the
    start of that intersection within t ≥ 0: 0 if the boxes overlap now, +inf if never.

    Parameters
    ----------
    box_a, box_b : array-like of shape (..., 5)
        ``[x, y, psi, length, width]``.
    v_a, v_b : array-like of shape (...)
        Speeds along the headings in m/s.

    Returns
    -------
    ndarray of shape (...)
        TTC in s.
    """
    return _ttc_thw(box_a, v_a, box_b, v_b)[0]


def time_headway(ego_box: ArrayLike, v_ego: ArrayLike, obj_box: ArrayLike) -> FloatArray:
    """Time headway: bumper-to-bumper gap to an object ahead in the ego's path / ego speed.

    In the ego's frame (x' along its heading), the object is "ahead in the path" when the
    lateral extents of the two boxes overlap (positive-area convention) and the object's
    centre is in front of the ego's centre. The gap is x' of the object's rear extent minus
    the ego's half length; the object's extents in that frame are those of its rotated box.
    THW = gap / v_ego; 0 when the boxes already overlap longitudinally (gap ≤ 0); +inf when
    the object is not ahead in the path or the ego stands still.

    Parameters
    ----------
    ego_box, obj_box : array-like of shape (..., 5)
    v_ego : array-like of shape (...)
        Ego speed in m/s.

    Returns
    -------
    ndarray of shape (...)
        THW in s.
    """
    return _ttc_thw(ego_box, v_ego, obj_box, 0.0)[1]


def _ttc_thw(box_a: ArrayLike, v_a: ArrayLike, box_b: ArrayLike, v_b: ArrayLike
             ) -> tuple[FloatArray, FloatArray]:
    a = _boxes(box_a, "box_a")
    b = _boxes(box_b, "box_b")
    va = np.asarray(v_a, dtype=np.float64)
    vb = np.asarray(v_b, dtype=np.float64)
    if not (np.isfinite(va).all() and np.isfinite(vb).all()):
        raise RiskcoreError("speeds must be finite")
    shape = np.broadcast_shapes(a.shape[:-1], b.shape[:-1], va.shape, vb.shape)
    a = np.ascontiguousarray(np.broadcast_to(a, (*shape, 5)).reshape(-1, 5))
    b = np.ascontiguousarray(np.broadcast_to(b, (*shape, 5)).reshape(-1, 5))
    va = np.ascontiguousarray(np.broadcast_to(va, shape).ravel())
    vb = np.ascontiguousarray(np.broadcast_to(vb, shape).ravel())
    ttc, thw = _kernels.ttc_thw_many(a, va, b, vb)
    return ttc.reshape(shape), thw.reshape(shape)
