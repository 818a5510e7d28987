#!/usr/bin/env python3
"""A camera that never stops, made from a log: publishes a bag's frames (Image, CameraInfo and the
camera's /tf) at IMAGE_RATE Hz on wall time, for as long as it runs. Each logged frame is held for
IMAGE_RATE / (the log's frame rate) images, as a 30 Hz camera moving at the log's speed would see
it, and the log is walked forward then backward, so that the path has no jump and time never goes
back. Every message gets the stamp of the moment it is sent.

Usage: soak_camera.py BAG [IMAGE_RATE]        (default 30)
"""
import sys

import rosbag
import rospy
from sensor_msgs.msg import CameraInfo, Image
from tf2_msgs.msg import TFMessage


def read_frames(path):
    """[(image, info, transform)] in log order, each triple taken at the image's stamp."""
    images, infos, transforms = [], {}, {}
    image_topic = info_topic = None
    with rosbag.Bag(path) as bag:
        for topic, msg, _ in bag.read_messages():
            kind = msg._type
            if kind == Image._type:
                image_topic = image_topic or topic
                images.append(msg)
            elif kind == CameraInfo._type:
                info_topic = info_topic or topic
                infos[msg.header.stamp] = msg
            elif kind == TFMessage._type:
                for t in msg.transforms:
                    transforms[t.header.stamp] = t
    frames = []
    for image in images:
        info, transform = infos.get(image.header.stamp), transforms.get(image.header.stamp)
        if info is not None and transform is not None:
            frames.append((image, info, transform))
    if len(frames) < 2:
        sys.exit("soak_camera: %s has fewer than two frames with an image, its camera_info and its /tf at one stamp" % path)
    span = (frames[-1][0].header.stamp - frames[0][0].header.stamp).to_sec()
    return frames, image_topic, info_topic, (len(frames) - 1) / span


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    rate_hz = float(sys.argv[2]) if len(sys.argv) > 2 else 30.0
    frames, image_topic, info_topic, log_fps = read_frames(sys.argv[1])
    hold = max(1, int(round(rate_hz / log_fps)))
    rospy.init_node("soak_camera")
    image_pub = rospy.Publisher(image_topic, Image, queue_size=2)
    info_pub = rospy.Publisher(info_topic, CameraInfo, queue_size=2)
    tf_pub = rospy.Publisher("/tf", TFMessage, queue_size=10)  # what tf2_ros's broadcaster sends
    rospy.loginfo("soak_camera: %d frames of %s at %.0f Hz, each held for %d images (the log's %.1f frames/s)",
                  len(frames), image_topic, rate_hz, hold, log_fps)
    order = list(range(len(frames))) + list(range(len(frames) - 2, 0, -1))  # forward, then back
    tick = rospy.Rate(rate_hz)
    sent = 0
    while not rospy.is_shutdown():
        image, info, transform = frames[order[(sent // hold) % len(order)]]
        stamp = rospy.Time.now()
        transform.header.stamp = info.header.stamp = image.header.stamp = stamp
        tf_pub.publish(TFMessage([transform]))
        info_pub.publish(info)
        image_pub.publish(image)
        sent += 1
        try:
            tick.sleep()
        except rospy.ROSInterruptException:
            break


if __name__ == "__main__":
    main()
