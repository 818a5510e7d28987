#!/usr/bin/env python3
"""The end of a replayed log, for scripts: asks the keyframe selector to send the keyframes that
still wait for a newer one (its ~flush service; no frame comes any more to release them) and
waits until fusion has fused them (the map is republished with the stamp of the last estimate it
fused). Run it once the log has ended, so that the selector sends nothing else meanwhile.

Usage: flush_replay.py [NAMESPACE] [TIMEOUT_S]     (defaults: /unsup_mvs, 120)
Exit status: 0 when the map includes every set the flush sent (or it sent none); 1 on a timeout
or a failed service call.
"""
import sys
import threading
import time

import rospy
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger
from unsup_mvs.msg import KeyframeSet


def main():
    ns = (sys.argv[1] if len(sys.argv) > 1 else "/unsup_mvs").rstrip("/")
    timeout = float(sys.argv[2]) if len(sys.argv) > 2 else 120.0
    # Replays run on simulated time, which stops with the log: every wait here is on the wall clock.
    rospy.init_node("flush_replay", anonymous=True, disable_signals=True)
    deadline = time.monotonic() + timeout

    flushed = []  # reference stamps of the sets the flush sent
    map_stamp = None
    changed = threading.Condition()

    def on_set(msg):
        with changed:
            flushed.append(msg.header.stamp)
            changed.notify_all()

    def on_map(msg):
        nonlocal map_stamp
        with changed:
            map_stamp = msg.header.stamp
            changed.notify_all()

    def wait_until(condition, what):
        with changed:
            while not condition():
                left = deadline - time.monotonic()
                if left <= 0:
                    print("flush_replay: %s did not happen within %.0f s" % (what, timeout), file=sys.stderr)
                    return False
                changed.wait(min(left, 0.5))
        return True

    sets = rospy.Subscriber(ns + "/keyframes", KeyframeSet, on_set, queue_size=10, buff_size=2 ** 26)
    rospy.Subscriber(ns + "/cloud", PointCloud2, on_map, queue_size=1, buff_size=2 ** 26)
    if not wait_until(lambda: sets.get_num_connections() > 0, "connecting to " + ns + "/keyframes"):
        return 1

    service = ns + "/keyframe_selector/flush"
    try:
        rospy.wait_for_service(service, timeout=max(1.0, deadline - time.monotonic()))
        reply = rospy.ServiceProxy(service, Trigger)()
    except (rospy.ROSException, rospy.ServiceException) as e:
        print("flush_replay: %s: %s" % (service, e), file=sys.stderr)
        return 1
    print("flush_replay: keyframe selector: %s" % reply.message)
    sent = int(reply.message.split()[1])  # "sent N keyframe set(s); ..."
    if sent == 0:
        return 0
    if not wait_until(lambda: len(flushed) >= sent, "receiving the %d flushed set(s)" % sent):
        return 1
    last = max(flushed)
    if not wait_until(lambda: map_stamp is not None and map_stamp >= last, "fusing the flushed set(s)"):
        return 1
    print("flush_replay: the map includes the flushed set(s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
