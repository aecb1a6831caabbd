"""marker_skeleton: the cameras' 2D marker tracks -> the 15 joints in 3D on /mvpose/skeleton (marker mode).

For each configured camera it subscribes /cam<K>/marker_tracks (from a marker_tracker in /cam<K>)
through the approximate-time synchroniser, and camera_info and camera_pose. Each marker is
triangulated from the cameras that detected it (marker_triangulation.py); one detected in fewer than
two cameras keeps its last 3D position and the skeleton is DEGRADED, naming it. Publishes
/mvpose/skeleton (reliable, the last one kept for late subscribers) and /mvpose/skeleton_markers.
"""
import time

import numpy as np
from mvpose_msgs.msg import MarkerTracks, Skeleton
from visualization_msgs.msg import MarkerArray

from mvpose_nodes.body_model import JOINT_NAMES
from mvpose_nodes.marker_triangulation import triangulate_markers
from mvpose_nodes.multi_camera_node import MultiCameraNode
from mvpose_nodes.rosconv import skeleton_markers, skeleton_message, tracks_from_message
from mvpose_nodes.rosutil import LATCHED, run_node


class MarkerSkeletonNode(MultiCameraNode):
    def __init__(self):
        super().__init__('marker_skeleton', {'marker_tracks': MarkerTracks},
                         'marker tracks are triangulated (each needs a marker_tracker in /cam<K>)')
        self.previous = None
        self.skeleton_publisher = self.create_publisher(Skeleton, '/mvpose/skeleton', LATCHED)
        self.marker_publisher = self.create_publisher(MarkerArray, '/mvpose/skeleton_markers', 10)
        self.get_logger().info(f'triangulating the markers of cameras {self.cameras}')

    def on_frame_set(self, frame_set):
        started = time.perf_counter()
        cameras, positions, flags = [], [], []
        for number in self.cameras:
            message = frame_set.messages.get((number, 'marker_tracks'))
            camera = self.camera(number) if message is not None else None
            if camera is None or message.status != MarkerTracks.STATUS_OK:
                continue
            try:
                tracked = tracks_from_message(message)
            except ValueError as error:
                self.report_once(f'tracks {number}', f'/cam{number}/marker_tracks: {error}; dropped')
                continue
            cameras.append(camera)
            positions.append(tracked[0])
            flags.append(tracked[1])
        stamp = frame_set.stamp_ns
        if len(cameras) < 2:
            self.report_once('few cameras', f'fewer than 2 cameras with tracked markers at {stamp} ns: no skeleton '
                                            '(logged once; the node keeps waiting)')
            return
        joints, used = triangulate_markers(cameras, np.array(positions), np.array(flags), self.previous)
        if not np.all(np.isfinite(joints)):
            self.report_once('first', 'a marker was not detected in 2 cameras before it was ever triangulated: '
                                      'no skeleton until every marker has been')
            return
        self.previous = joints
        kept = [name for name, count in zip(JOINT_NAMES, used) if count < 2]
        degraded = bool(kept) or bool(frame_set.missing_groups) or len(cameras) < len(self.cameras)
        reason = (f'kept from before (seen in < 2 cameras): {", ".join(kept)}; ' if kept else '') + \
                 f'cameras: {sorted(c.number for c in cameras)}'
        status = Skeleton.STATUS_DEGRADED if degraded else Skeleton.STATUS_OK
        message = skeleton_message(joints, stamp, status=status, status_message=reason if degraded else '',
                                   fit_time=time.perf_counter() - started)
        self.skeleton_publisher.publish(message)
        self.marker_publisher.publish(skeleton_markers(joints, message.header, status))


def main(args=None):
    return run_node(MarkerSkeletonNode, args)
