"""skeleton_fitter: the cameras' features -> the fitted 15-joint skeleton (paper 000 Sec. 4–6, paper 004).

For each configured camera it subscribes /cam<K>/skin_ellipses and /cam<K>/labelled_contour (through
an approximate-time synchroniser: fitting/sync.py) and the camera's camera_info and camera_pose. Every synchronised frame set is fitted (ros/frame_set_fitting.py) and published as
/mvpose/skeleton (mvpose_msgs/Skeleton: joint poses, the 29 parameters, the six stages), the 29
parameters as /mvpose/joint_states (sensor_msgs/JointState), and /mvpose/skeleton_markers
(visualization_msgs/MarkerArray in `world`, for RViz and Foxglove). A camera whose features stop is
left out after camera_timeout (status DEGRADED) and rejoins when they come back. A frame set with fewer
than two cameras seeing the person gets STATUS_LOST, repeating the last fitted pose.
"""
from mvpose_msgs.msg import LabelledContour, Skeleton, SkinEllipseArray
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray

from mvpose_nodes.ros.conversions import joint_state, joints_from_skeleton, skeleton_markers
from mvpose_nodes.ros.frame_set_fitting import FrameSetFitter
from mvpose_nodes.ros.helpers import LATCHED, run_node
from mvpose_nodes.ros.multi_camera import MultiCameraNode
from mvpose_nodes.ros.params import SKELETON_FITTER, fitter_settings_from

# The silhouette is not an input: the labelled contour is its outline, and all the fit reads of it.
FEATURES = {'skin_ellipses': SkinEllipseArray, 'labelled_contour': LabelledContour}


class SkeletonFitterNode(MultiCameraNode):
    def __init__(self):
        super().__init__('skeleton_fitter', FEATURES, SKELETON_FITTER)
        self.fitting = FrameSetFitter(fitter_settings_from(self.values), self.cameras)
        self.skeleton_publisher = self.create_publisher(Skeleton, '/mvpose/skeleton', LATCHED)
        self.joint_state_publisher = self.create_publisher(JointState, '/mvpose/joint_states', 10)
        self.marker_publisher = self.create_publisher(MarkerArray, '/mvpose/skeleton_markers', 10)
        self.get_logger().info(f'fitting cameras {self.cameras}')

    def on_frame_set(self, frame_set):
        features = {number: (self.camera(number), frame_set.messages[(number, 'skin_ellipses')],
                             frame_set.messages[(number, 'labelled_contour')])
                    for number in self.cameras if (number, 'labelled_contour') in frame_set.messages}
        result = self.fitting.fit(frame_set.stamp_ns, features, frame_set.missing_groups)
        for cause, text in result.problems:
            self.report_once(cause, text)
        if result.message is not None:
            message = result.message
            self.skeleton_publisher.publish(message)
            self.joint_state_publisher.publish(joint_state(result.parameters, message.header))
            self.marker_publisher.publish(skeleton_markers(joints_from_skeleton(message), message.header,
                                                           message.status))


def main(args=None):
    return run_node(SkeletonFitterNode, args)
