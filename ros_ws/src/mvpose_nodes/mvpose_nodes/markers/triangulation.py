"""Marker mode in 3D (beyond paper 001, which tracks in one 2D view): the 2D marker tracks of all
cameras triangulated into the 15 joints, each marker from the cameras that detected it."""
import numpy as np

from mvpose_nodes.markers.detection import FLAG_DETECTED, FLAG_LOST
from mvpose_nodes.body.triangulation import triangulate


def triangulate_markers(cameras, positions, flags, previous=None):
    """The 15 joints from C cameras' marker tracks.

    cameras: C Camera objects; positions: (C, 15, 2) [px]; flags: (C, 15) FLAG_* (markers.py). A marker
    is triangulated (DLT, triangulation.triangulate) from the cameras where it was detected; with fewer
    than 2 such cameras it keeps `previous` (15, 3) [m]. Without a previous position (the first frames),
    such a marker is triangulated from the trackers' predictions too (not lost ones), so that a marker
    hidden from all but one camera at the start still gets a place; NaN if even that fails. Returns
    (joints (15, 3) float64 [m], cameras that detected each marker (15,) int)."""
    positions = np.asarray(positions, dtype=float)
    detected = np.asarray(flags) == FLAG_DETECTED
    count = positions.shape[1]
    joints = np.full((count, 3), np.nan) if previous is None else np.array(previous, dtype=float)
    used = detected.sum(axis=0)
    estimated = np.asarray(flags) != FLAG_LOST
    for marker in range(count):
        found = triangulate(cameras, positions[:, marker], detected[:, marker].astype(float))
        if found is None and previous is None:
            found = triangulate(cameras, positions[:, marker], estimated[:, marker].astype(float))
        if found is not None:
            joints[marker] = found[0]
    return joints, used
