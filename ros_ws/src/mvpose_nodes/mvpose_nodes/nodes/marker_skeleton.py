"""marker_skeleton: the cameras' 2D marker tracks -> the 15 joint markers in 3D on /mvpose/skeleton (marker mode).

For each configured camera it subscribes /cam<K>/marker_tracks (from a marker_tracker in /cam<K>)
through the approximate-time synchroniser, and camera_info and camera_pose. Each frame set is fused
across the cameras (marker_views.MarkerViews: each marker triangulated from the views whose detections
agree, hidden ones predicted, every camera's blobs paired again with the projected markers). Publishes
/mvpose/skeleton (reliable, the last one kept for late subscribers; DEGRADED, naming them, when markers
were not triangulated from two views), /mvpose/skeleton_markers, and per camera
/cam<K>/marker_tracks_fused, the tracks corrected by the other views, which that camera's
marker_tracker takes up before its next image.
"""
import time

import numpy as np
from mvpose_msgs.msg import MarkerTracks, Skeleton
from visualization_msgs.msg import MarkerArray

from mvpose_nodes.body.model import JOINT_NAMES
from mvpose_nodes.markers.views import MarkerViews
from mvpose_nodes.markers.detection import FLAG_LOST
from mvpose_nodes.ros.multi_camera import MultiCameraNode
from mvpose_nodes.ros.conversions import blobs_from_message, marker_tracks, skeleton_markers, skeleton_message, \
    tracks_from_message
from mvpose_nodes.ros.diagnostics import NodeDiagnostics
from mvpose_nodes.ros.helpers import LATCHED, run_node
from mvpose_nodes.ros.params import MARKER_SKELETON

STREAM_DEPTH = 10


class MarkerSkeletonNode(MultiCameraNode):
    def __init__(self):
        super().__init__('marker_skeleton', {'marker_tracks': MarkerTracks}, MARKER_SKELETON)
        self.views = None
        self.skeleton_publisher = self.create_publisher(Skeleton, '/mvpose/skeleton', LATCHED)
        self.marker_publisher = self.create_publisher(MarkerArray, '/mvpose/skeleton_markers', 10)
        self.fused_publishers = {k: self.create_publisher(MarkerTracks, f'/cam{k}/marker_tracks_fused', STREAM_DEPTH)
                                 for k in self.cameras}
        self.counts = {'frame sets': 0, 'skeletons': 0, 'skeletons degraded': 0}
        self.diagnostics = NodeDiagnostics(self, self.state)
        self.get_logger().info(f'fusing the marker tracks of cameras {self.cameras}')

    def state(self):
        """The node's diagnostics: level, message and counters (ros/diagnostics.py)."""
        counts = self.counts
        message = (f"{counts['frame sets']} frame sets, {counts['skeletons']} skeletons "
                   f"({counts['skeletons degraded']} degraded)")
        return ('warn' if counts['skeletons degraded'] else 'ok'), message, counts

    def on_frame_set(self, frame_set):
        self.counts['frame sets'] += 1
        started = time.perf_counter()
        count = len(self.cameras)
        positions = np.full((count, len(JOINT_NAMES), 2), np.nan)
        flags = np.full((count, len(JOINT_NAMES)), FLAG_LOST, np.uint8)
        blobs = [np.zeros((0, 2))] * count
        headers = {}
        for c, number in enumerate(self.cameras):
            message = frame_set.messages.get((number, 'marker_tracks'))
            if message is None or self.camera(number) is None or message.status != MarkerTracks.STATUS_OK:
                continue
            try:
                positions[c], flags[c] = tracks_from_message(message)
                blobs[c] = blobs_from_message(message)
            except ValueError as error:
                positions[c], flags[c] = np.nan, FLAG_LOST
                self.report_once(f'tracks {number}', f'/cam{number}/marker_tracks: {error}; dropped')
                continue
            headers[number] = message.header
        stamp = frame_set.stamp_ns
        if len(headers) < 2:
            self.report_once('few cameras', f'fewer than 2 cameras with tracked markers at {stamp} ns: no skeleton '
                                            '(logged once; the node keeps waiting)')
            return
        if self.views is None:
            if len(headers) < count:
                return self.report_once('start', 'marker fusion starts at the first frame set with every camera\'s '
                                                 'tracks (and calibration)')
            self.views = MarkerViews([self.camera(k) for k in self.cameras])
            self.views.start(positions, flags)
        points, fused, fused_flags = self.views.fuse(positions, flags, blobs)
        for c, number in enumerate(self.cameras):
            if number in headers:
                self.fused_publishers[number].publish(marker_tracks(headers[number], fused[c], fused_flags[c]))
        if not np.all(np.isfinite(points)):
            return self.report_once('first', 'a marker was never placed in 2 cameras: no skeleton until it is')
        weak = [name for name, support in zip(JOINT_NAMES, self.views.support) if support < 2]
        degraded = bool(weak) or bool(frame_set.missing_groups) or len(headers) < count
        reason = (f'predicted (seen in < 2 cameras): {", ".join(weak)}; ' if weak else '') + \
                 f'cameras: {sorted(headers)}'
        status = Skeleton.STATUS_DEGRADED if degraded else Skeleton.STATUS_OK
        message = skeleton_message(points, stamp, status=status, status_message=reason if degraded else '',
                                   fit_time=time.perf_counter() - started)
        self.skeleton_publisher.publish(message)
        self.counts['skeletons'] += 1
        self.counts['skeletons degraded'] += degraded
        self.marker_publisher.publish(skeleton_markers(points, message.header, status))


def main(args=None):
    return run_node(MarkerSkeletonNode, args)
