"""skeleton_fitter: the cameras' features -> the fitted 15-joint skeleton (paper 000 Sec. 4–6, paper 004).

For each configured camera it subscribes /cam<K>/silhouette, /cam<K>/skin_ellipses and
/cam<K>/labelled_contour (through an approximate-time synchroniser: sync.py) and the camera's
camera_info and camera_pose. Every synchronised frame set is fitted (fitting/fitter.py) and published as
/mvpose/skeleton (mvpose_msgs/Skeleton: joint poses, the 29 parameters, the six stages), the 29
parameters as /mvpose/joint_states (sensor_msgs/JointState), and /mvpose/skeleton_markers
(visualization_msgs/MarkerArray in `world`, for RViz and Foxglove). A camera whose features stop is
left out after camera_timeout (status DEGRADED) and rejoins when they come back. A frame set with fewer
than two cameras seeing the person gets STATUS_LOST, repeating the last fitted pose.
"""
from mvpose_msgs.msg import LabelledContour, Skeleton, SkinEllipseArray
from sensor_msgs.msg import Image, JointState
from visualization_msgs.msg import MarkerArray

from mvpose_nodes.body.kinematics import forward_kinematics
from mvpose_nodes.body.model import PARAMETER_NAMES
from mvpose_nodes.fitting.fitter import SkeletonFitter, view_from_features
from mvpose_nodes.ros.multi_camera import MultiCameraNode
from mvpose_nodes.ros.conversions import (contour_from_message, joint_state, joints_from_skeleton,
                                          keypoints_from_messages, skeleton_markers, skeleton_message, stage_messages)
from mvpose_nodes.ros.helpers import LATCHED, run_node
from mvpose_nodes.ros.params import SKELETON_FITTER, fitter_settings_from

FEATURES = {'silhouette': Image, 'skin_ellipses': SkinEllipseArray, 'labelled_contour': LabelledContour}


class SkeletonFitterNode(MultiCameraNode):
    def __init__(self):
        super().__init__('skeleton_fitter', FEATURES, SKELETON_FITTER)
        self.fitter = SkeletonFitter(fitter_settings_from(self.values))
        self.skeleton_publisher = self.create_publisher(Skeleton, '/mvpose/skeleton', LATCHED)
        self.joint_state_publisher = self.create_publisher(JointState, '/mvpose/joint_states', 10)
        self.marker_publisher = self.create_publisher(MarkerArray, '/mvpose/skeleton_markers', 10)
        self.get_logger().info(f'fitting cameras {self.cameras}')

    def on_frame_set(self, frame_set):
        views = []
        for number in self.cameras:
            if (number, 'labelled_contour') not in frame_set.messages:
                continue
            camera = self.camera(number)
            ellipses = frame_set.messages[(number, 'skin_ellipses')]
            contour = frame_set.messages[(number, 'labelled_contour')]
            if camera is None or contour.status != LabelledContour.STATUS_OK:
                continue
            try:
                labels = contour_from_message(contour)
            except ValueError as error:
                self.report_once(f'contour {number}', f'/cam{number}/labelled_contour: {error}; dropped')
                continue
            views.append(view_from_features(camera, keypoints_from_messages(ellipses, contour), labels,
                                            ellipses.face_visibility))
        stamp = frame_set.stamp_ns
        if len(views) < 2:
            return self.lost(stamp, 'few views', f'fewer than 2 cameras with a person at {stamp} ns')
        try:
            fit = self.fitter.fit(stamp / 1e9, views)
        except ValueError as error:
            return self.lost(stamp, 'fit', f'no fit at {stamp} ns: {error}')
        used = {v.camera.number for v in views}
        degraded = bool(frame_set.missing_groups) or used != set(self.cameras) or not all(s.fitted for s in fit.stages)
        status = (Skeleton.STATUS_INITIALISING if fit.initialised
                  else Skeleton.STATUS_DEGRADED if degraded else Skeleton.STATUS_OK)
        reason = f'cameras used: {sorted(used)}' if degraded else ''
        message = skeleton_message(fit.joints, stamp, parameter_names=list(PARAMETER_NAMES),
                                   parameters=fit.parameters.tolist(), stages=stage_messages(fit.stages),
                                   status=status, status_message=reason, fit_time=fit.seconds)
        self.publish(message, fit.parameters)

    def lost(self, stamp, cause, reason):
        """No person to fit in this frame set: a Skeleton with STATUS_LOST repeating the last fitted pose
        (none before the first fit), and the reason logged once."""
        self.report_once(cause, f'{reason} (logged once; STATUS_LOST with the last pose while it lasts)')
        if self.fitter.parameters is None:
            return
        joints, _ = forward_kinematics(self.fitter.parameters, self.fitter.lengths)
        message = skeleton_message(joints, stamp, parameter_names=list(PARAMETER_NAMES),
                                   parameters=self.fitter.parameters.tolist(), status=Skeleton.STATUS_LOST,
                                   status_message=reason)
        self.publish(message, self.fitter.parameters)

    def publish(self, message, parameters):
        joints = joints_from_skeleton(message)
        self.skeleton_publisher.publish(message)
        self.joint_state_publisher.publish(joint_state(parameters, message.header))
        self.marker_publisher.publish(skeleton_markers(joints, message.header, message.status))


def main(args=None):
    return run_node(SkeletonFitterNode, args)
