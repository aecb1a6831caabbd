"""skeleton_fitter: the cameras' features -> the fitted 15-joint skeleton (paper 000 Sec. 4–6, paper 004).

For each configured camera it subscribes /cam<K>/skin_ellipses and /cam<K>/labelled_contour (through
an approximate-time synchroniser: fitting/sync.py) and the camera's camera_info and camera_pose. The
synchronised frame sets are fitted (ros/frame_set_fitting.py) in two worker threads, one making a set's
distance maps while the other fits the set before it: when sets come faster than the fitter, the stale
ones are skipped (pending_frame_sets; counted in the next status_message and on /diagnostics) rather
than queued. Each fit is published as /mvpose/skeleton (mvpose_msgs/Skeleton: joint
poses, the 29 parameters, the six stages), the 29 parameters as /mvpose/joint_states
(sensor_msgs/JointState), and /mvpose/skeleton_markers (visualization_msgs/MarkerArray in `world`, for
RViz and Foxglove); the node's state and CPU per stage once a second on /diagnostics
(diagnostic_msgs/DiagnosticArray). A camera whose features stop is left out after camera_timeout
(status DEGRADED) and rejoins when they come back. A frame set with fewer than two cameras seeing the
person gets STATUS_LOST, repeating the last fitted pose (before the first fit: STATUS_INITIALISING with a
standing best guess). When the input stops for camera_timeout, the frame sets still in the synchronisers are
flushed and fitted (a bag's end); a bag played again starts them afresh.

With request_frames (the default) the fitter also paces the cameras: it synchronises the stamps they
announce on /cam<K>/frame_available (std_msgs/Header, one per image) and, each time nothing waits before
its two stages (and, with request_overlap below 2, the stages it names are idle; both while a start is
fitted), asks every camera for the newest announced set on /cam<K>/frame_request (std_msgs/Header, that
camera's image stamp). Cameras that follow requests (camera_features' follow_requests) compute features
only for those: frames the graph cannot keep up with are skipped whole, before any camera spends CPU on
them, and counted as skipped.
"""
import threading
import time

import cv2
from mvpose_msgs.msg import LabelledContour, Skeleton, SkinEllipseArray
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from mvpose_nodes.fitting.fitter import warm_up
from mvpose_nodes.fitting.hypotheses import HYPOTHESES_POOL
from mvpose_nodes.fitting.sync import FrameRequests, PendingSets, ready_to_request
from mvpose_nodes.ros.conversions import joint_state, joints_from_skeleton, skeleton_markers, stamp_ns
from mvpose_nodes.ros.diagnostics import NodeDiagnostics
from mvpose_nodes.ros.frame_set_fitting import FrameSetFitter
from mvpose_nodes.ros.helpers import LATCHED, run_node
from mvpose_nodes.ros.multi_camera import MultiCameraNode
from mvpose_nodes.ros.params import SKELETON_FITTER, fitter_settings_from

# The silhouette is not an input: the labelled contour is its outline, and all the fit reads of it.
FEATURES = {'skin_ellipses': SkinEllipseArray, 'labelled_contour': LabelledContour}
STATUS_NAMES = {Skeleton.STATUS_OK: 'OK', Skeleton.STATUS_INITIALISING: 'INITIALISING',
                Skeleton.STATUS_DEGRADED: 'DEGRADED', Skeleton.STATUS_LOST: 'LOST'}


class SkeletonFitterNode(MultiCameraNode):
    def __init__(self):
        super().__init__('skeleton_fitter', FEATURES, SKELETON_FITTER)
        cv2.setNumThreads(1)
        warm_up()   # the compiled objective loaded (or compiled, the first time) before any frame set waits
        self.fitting = FrameSetFitter(fitter_settings_from(self.values), self.cameras, self.clock,
                                      threads=self.values['fit_threads'])
        self.skeleton_publisher = self.create_publisher(Skeleton, '/mvpose/skeleton', LATCHED)
        self.joint_state_publisher = self.create_publisher(JointState, '/mvpose/joint_states', 10)
        self.marker_publisher = self.create_publisher(MarkerArray, '/mvpose/skeleton_markers', 10)
        # Two worker threads, a pipeline: 'preparing' makes a frame set's distance maps (OpenCV, without
        # the GIL) while 'fitting' fits the one before (compiled, without the GIL), so the fitter's two
        # halves use both cores. Before each, at most pending_frame_sets wait (the oldest are skipped), so
        # a fast input never builds a backlog.
        self.pending = PendingSets(self.values['pending_frame_sets'])
        self.prepared = PendingSets(self.values['pending_frame_sets'])
        self.counts = {'frame sets fitted': 0, 'frame sets skipped (stale)': 0, 'frame sets without a fit': 0,
                       'frame sets guessed (before the first fit)': 0}
        self.requests = None
        if self.values['request_frames']:
            self.requests = FrameRequests(self.values['camera_timeout'])
            self.announcements = self.synchronizer(['frame_available'])
            self.request_publishers = {k: self.create_publisher(Header, f'/cam{k}/frame_request', 10)
                                       for k in self.cameras}
            for k in self.cameras:
                self.create_subscription(Header, f'/cam{k}/frame_available',
                                         lambda header, k=k: self.on_announcement(k, header), 10)
            self.create_timer(0.1, self.request_next)   # gives up unanswered requests
        self.last_status = None
        self.working = {'preparing': False, 'fitting': False}   # each stage busy with a set (request_overlap)
        # Whether the set in (or handed to) the fit stage starts the fit (ready_to_request): noted when the set is
        # handed on, since the fitter's own starts_next turns False part-way through the start it names.
        self.fit_starts = False
        self.workers = {name: threading.Thread(target=work, name=name, daemon=True)
                        for name, work in (('preparing', self.preparing_loop), ('fitting', self.fitting_loop))}
        self.diagnostics = NodeDiagnostics(self, self.state, [self.clock], self.workers, pools=[HYPOTHESES_POOL])
        for worker in self.workers.values():
            worker.start()
        self.get_logger().info(f'fitting cameras {self.cameras}')

    def synchronised(self, frame_set):
        # The request is answered when its features are in, even while the set waits for a camera's
        # calibration: the cameras go on computing the next sets meanwhile, and none is lost to a request
        # given up.
        if self.requests is not None:
            self.requests.received(frame_set.stamp_ns)

    def on_frame_set(self, frame_set):
        self.pending.put(frame_set)

    def on_announcement(self, camera, header):
        # Input too: an image the cameras are still announcing (one before another) is not the end of the input,
        # which the idle flush would cut short, asking some cameras alone for it.
        self.last_input = time.monotonic()
        with self.clock('sync'):
            for announced in self.announcements.add((camera, 'frame_available'), stamp_ns(header), header):
                self.requests.announce(announced)
        self.request_next()

    def end_of_input(self):
        """The last announced frame sets too, so that the cameras are asked for them."""
        if self.requests is not None:
            with self.clock('sync'):
                for announced in self.announcements.flush():
                    self.requests.announce(announced)
            self.request_next()

    def request_next(self):
        """Ask the cameras for the newest announced frame set if nothing waits before the fitter's stages and
        those request_overlap allows are free (called from the executor and from both worker threads;
        rcl_publish is thread-safe)."""
        if self.requests is None:
            return
        ready = ready_to_request(len(self.pending) or len(self.prepared),
                                 (self.working['preparing'], self.working['fitting']), self.values['request_overlap'],
                                 self.fit_starts)
        requested = self.requests.next_request(time.monotonic(), ready=ready)
        if requested is not None:
            for (k, _), header in requested.messages.items():
                self.request_publishers[k].publish(header)

    def preparing_loop(self):
        """The 'preparing' thread: frame sets -> fitting's PreparedSets."""
        while not self.pending.closed:
            frame_set = self.pending.take(timeout=0.5)
            if frame_set is None:
                continue
            self.working['preparing'] = True
            self.request_next()
            try:
                features = {number: (self.camera(number), frame_set.messages[(number, 'skin_ellipses')],
                                     frame_set.messages[(number, 'labelled_contour')])
                            for number in self.cameras if (number, 'labelled_contour') in frame_set.messages}
                prepared = self.fitting.prepare(frame_set.stamp_ns, features, frame_set.missing_groups)
                self.fit_starts = self.fitting.starts_next
                self.working['fitting'] = True   # handed on: never a moment in neither stage
                self.prepared.put(prepared)
            except Exception as error:   # a bug must not stop the fitting: say it, drop the set, go on
                self.drop(frame_set.stamp_ns, error)
            self.working['preparing'] = False
            self.request_next()

    def fitting_loop(self):
        """The 'fitting' thread: PreparedSets -> published skeletons."""
        reported_skips = 0
        while not self.prepared.closed:
            prepared = self.prepared.take(timeout=0.5)
            if prepared is None:
                continue
            self.fit_starts = self.fitting.starts_next
            self.working['fitting'] = True
            self.request_next()
            skips = self.pending.skipped + self.prepared.skipped + (self.requests.skipped if self.requests else 0)
            skipped, reported_skips = skips - reported_skips, skips
            try:
                self.fit_and_publish(prepared, skipped)
            except Exception as error:
                self.drop(prepared.stamp_ns, error)
            self.working['fitting'] = False
            self.request_next()

    def drop(self, stamp_ns, error):
        self.get_logger().error(f'frame set {stamp_ns} ns dropped: {type(error).__name__}: {error}')

    def fit_and_publish(self, prepared, skipped):
        result = self.fitting.fit_prepared(prepared, skipped)
        self.counts['frame sets skipped (stale)'] += skipped
        for cause, text in result.problems:
            self.report_once(cause, text)
        if result.guessed:
            self.counts['frame sets guessed (before the first fit)'] += 1
        elif result.message is None or result.message.status == Skeleton.STATUS_LOST:
            self.counts['frame sets without a fit'] += 1
        else:
            self.counts['frame sets fitted'] += 1
        if result.message is not None:
            message = result.message
            self.last_status = message.status
            with self.clock('publish'):
                self.skeleton_publisher.publish(message)
                self.joint_state_publisher.publish(joint_state(result.parameters, message.header))
                self.marker_publisher.publish(skeleton_markers(joints_from_skeleton(message), message.header,
                                                               message.status))

    def state(self):
        """The node's diagnostics: level, message and counters (ros/diagnostics.py)."""
        level = 'ok' if self.last_status in (Skeleton.STATUS_OK, Skeleton.STATUS_INITIALISING) else 'warn'
        counts = dict(self.counts)
        if self.requests is not None:
            counts['frame requests unanswered'] = self.requests.unanswered
        message = (f"{self.counts['frame sets fitted']} frame sets fitted, "
                   f"{self.counts['frame sets skipped (stale)']} skipped (stale), last status "
                   f"{STATUS_NAMES.get(self.last_status, 'none yet')}")
        return level, message, counts

    def destroy_node(self):
        self.pending.close()
        self.prepared.close()
        for worker in self.workers.values():
            worker.join(timeout=10)
        super().destroy_node()


def main(args=None):
    return run_node(SkeletonFitterNode, args)
