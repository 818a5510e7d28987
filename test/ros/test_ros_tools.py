#!/usr/bin/python3
"""The ROS command-line tools on unsup_mvs's own types (ros_tools.test).

rostopic/rosservice/rosmsg load message classes from the generated Python code (genpy in the devel
or install space) and from the python3-*-msgs packages (std_srvs/Trigger): this test runs the
tools as a user would and checks what they print. Every wait is on a condition (a service
appearing, `rostopic echo -n 1` returning), bounded by a timeout.
"""
import os
import shutil
import subprocess
import sys
import threading
import unittest

import numpy as np
import rospy
import rostest
from geometry_msgs.msg import Pose
from sensor_msgs.msg import CameraInfo, Image
from unsup_mvs.msg import KeyframeSet

PKG = 'unsup_mvs'
TIMEOUT = 120.0


def run(args, timeout=TIMEOUT):
    """Runs a ROS tool; returns (exit code, stdout + stderr)."""
    done = subprocess.run(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=timeout,
                          universal_newlines=True)
    return done.returncode, done.stdout


def camera_info(width, height):
    info = CameraInfo()
    info.header.frame_id = 'camera'
    info.width, info.height = width, height
    f = 0.8 * width
    info.K = [f, 0, width / 2.0, 0, f, height / 2.0, 0, 0, 1]
    info.P = [f, 0, width / 2.0, 0, 0, f, height / 2.0, 0, 0, 0, 1, 0]
    info.R = [1, 0, 0, 0, 1, 0, 0, 0, 1]
    return info


def rgb_image(pixels):
    msg = Image()
    msg.header.frame_id = 'camera'
    msg.height, msg.width = pixels.shape[:2]
    msg.encoding = 'rgb8'
    msg.step = 3 * msg.width
    msg.data = pixels.tobytes()
    return msg


def pose_at(x):
    pose = Pose()
    pose.position.x = x
    pose.orientation.w = 1.0
    return pose


def keyframe_set(reference_id):
    """A textured plane seen by three cameras 10 cm apart (enough for a depth map)."""
    width, height = 128, 96
    rng = np.random.RandomState(reference_id)
    texture = rng.randint(0, 256, size=(height, width + 40, 3)).astype(np.uint8)
    msg = KeyframeSet()
    msg.header.stamp = rospy.Time.now()
    msg.header.frame_id = 'world'
    msg.reference_id = reference_id
    msg.reference_image = rgb_image(texture[:, 20:20 + width].copy())
    msg.reference_info = camera_info(width, height)
    msg.reference_pose = pose_at(0.0)
    for i, shift in enumerate((10, 30)):
        msg.source_ids.append(reference_id + 1000 + i)
        msg.source_images.append(rgb_image(texture[:, shift:shift + width].copy()))
        msg.source_infos.append(camera_info(width, height))
        msg.source_poses.append(pose_at((20 - shift) * 0.01))
    msg.depth_min, msg.depth_max = 1.0, 5.0
    return msg


class RosToolsTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node('test_ros_tools')
        cls.work = rospy.get_param('~work_dir')
        cls.model = rospy.get_param('~model')
        os.makedirs(os.path.join(cls.work, 'models'), exist_ok=True)
        # The trainer compares a new model with the served one: it must be readable.
        shutil.copyfile(cls.model, os.path.join(cls.work, 'served.pt'))
        for service in ('/inference/reload_model', '/fusion/save_cloud', '/fusion/reset',
                        '/trainer/status', '/trainer/fine_tune', '/trainer/cancel'):
            rospy.wait_for_service(service, timeout=TIMEOUT)

    def test_rosmsg_show_our_messages(self):
        for msg, field in (('DepthEstimate', 'float32 inference_seconds'),
                           ('KeyframeSet', 'uint32[] source_ids'),
                           ('TrainingProgress', 'float32 eta_seconds')):
            code, out = run(['rosmsg', 'show', PKG + '/' + msg])
            self.assertEqual(code, 0, out)
            self.assertIn(field, out)

    def test_rossrv_show_our_services(self):
        for srv, field in (('FineTune', 'string init_checkpoint'), ('ReloadModel', 'string checkpoint'),
                           ('ResetFusion', 'bool success'), ('SaveCloud', 'uint64 num_points')):
            code, out = run(['rossrv', 'show', PKG + '/' + srv])
            self.assertEqual(code, 0, out)
            self.assertIn(field, out)

    def test_rosservice_type_and_call(self):
        for service, srv_type in (('/trainer/status', 'std_srvs/Trigger'),
                                  ('/fusion/reset', PKG + '/ResetFusion'),
                                  ('/fusion/save_cloud', PKG + '/SaveCloud'),
                                  ('/inference/reload_model', PKG + '/ReloadModel')):
            code, out = run(['rosservice', 'type', service])
            self.assertEqual((code, out.strip()), (0, srv_type))

        code, out = run(['rosservice', 'call', '/fusion/reset'])
        self.assertEqual(code, 0, out)
        self.assertIn('success: True', out)
        # Nothing fused after a reset: save_cloud answers (refusing), and writes nothing.
        code, out = run(['rosservice', 'call', '/fusion/save_cloud', "path: 'empty.ply'"])
        self.assertEqual(code, 0, out)
        self.assertIn('success: False', out)
        self.assertIn('num_points: 0', out)
        self.assertFalse(os.path.exists(os.path.join(self.work, 'empty.ply')))

        code, out = run(['rosservice', 'call', '/inference/reload_model', "checkpoint: '%s'" % self.model])
        self.assertEqual(code, 0, out)
        self.assertIn('success: True', out)
        code, out = run(['rosservice', 'call', '/inference/reload_model', "checkpoint: '/nonexistent.pt'"])
        self.assertEqual(code, 0, out)
        self.assertIn('success: False', out)

    def test_rostopic_echo_keyframes_and_depth(self):
        publisher = rospy.Publisher('/keyframes', KeyframeSet, queue_size=1)
        stop = threading.Event()

        def publish_until_stopped():
            reference_id = 1
            while not stop.is_set() and not rospy.is_shutdown():
                publisher.publish(keyframe_set(reference_id))
                reference_id += 1
                stop.wait(0.5)
        thread = threading.Thread(target=publish_until_stopped)
        thread.start()
        try:
            code, out = run(['rostopic', 'echo', '-n', '1', '--noarr', '/keyframes'])
            self.assertEqual(code, 0, out)
            self.assertIn('reference_id:', out)
            self.assertIn('depth_max: 5.0', out)
            # Inference turns a set into a DepthEstimate (the model runs on the CPU: allow time).
            code, out = run(['rostopic', 'echo', '-n', '1', '--noarr', '/depth_estimate'], timeout=240)
            self.assertEqual(code, 0, out)
            self.assertIn('keyframe_id:', out)
            self.assertIn('world_frame: "world"', out)
        finally:
            stop.set()
            thread.join()
        for topic, msg_type in (('/keyframes', PKG + '/KeyframeSet'), ('/depth_estimate', PKG + '/DepthEstimate')):
            code, out = run(['rostopic', 'type', topic])
            self.assertEqual((code, out.strip()), (0, msg_type))

    def test_trainer_status_and_progress(self):
        code, out = run(['rosservice', 'call', '/trainer/status'])
        self.assertEqual(code, 0, out)
        self.assertIn('success: False', out)  # no job yet
        # A readable file that is not a bag: the job is accepted, announced on ~progress (latched),
        # and fails in `umvs train`.
        not_a_bag = os.path.join(self.work, 'not_a_bag.bag')
        with open(not_a_bag, 'w') as f:
            f.write('not a bag\n')
        request = "{bags: ['%s'], init_checkpoint: '%s', steps: 1, output: ''}" % (not_a_bag, self.model)
        code, out = run(['rosservice', 'call', '/trainer/fine_tune', request])
        self.assertEqual(code, 0, out)
        self.assertIn('accepted: True', out)
        code, out = run(['rostopic', 'echo', '-n', '1', '/trainer/progress'])
        self.assertEqual(code, 0, out)
        self.assertIn('job_id: "', out)
        self.assertIn('state: "', out)
        code, out = run(['rostopic', 'type', '/trainer/progress'])
        self.assertEqual((code, out.strip()), (0, PKG + '/TrainingProgress'))
        run(['rosservice', 'call', '/trainer/cancel'])  # the job may have failed already


if __name__ == '__main__':
    rostest.rosrun(PKG, 'test_ros_tools', RosToolsTest, sys.argv)
