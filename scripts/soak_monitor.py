#!/usr/bin/env python3
"""Watches a running pipeline for a while and says whether it held up: every SAMPLE seconds it
records each node's resident memory (VmRSS) and CPU use (% of one core since the last sample), the
keyframe sets inference processed, dropped and failed (its ~stats service) and the fused cloud's
points, into CSV. At the end it fails (exit 1) when
  - a node died or was restarted (its process is gone or another took its name),
  - a node's memory kept growing after the warm-up: the least-squares line through its samples after
    WARMUP minutes rises by more than max(TOLERANCE_MB, 5 % of its size) over that time,
  - a keyframe set failed, or no set was processed after the warm-up.

Usage: soak_monitor.py NS MINUTES SAMPLE_S WARMUP_MIN CSV [TOLERANCE_MB]
  e.g. soak_monitor.py /unsup_mvs 60 60 10 soak.csv 32
"""
import csv
import os
import re
import sys
import time
import xmlrpc.client

import rosgraph
import rospy
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger

STATS = re.compile(r"(\d+) keyframe sets processed, (\d+) dropped \(stale\), (\d+) failed")
CLK_TCK = os.sysconf("SC_CLK_TCK")


def node_pids(ns):
    """{node name: pid} of every node under the namespace (nodelets share their manager's pid)."""
    master = rosgraph.Master("/soak_monitor")
    names = set()
    for group in master.getSystemState():
        for _, nodes in group:
            names.update(n for n in nodes if n.startswith(ns + "/"))
    pids = {}
    for name in sorted(names):
        try:
            code, _, pid = xmlrpc.client.ServerProxy(master.lookupNode(name)).getPid("/soak_monitor")
            if code == 1:
                pids[name] = pid
        except (OSError, rosgraph.MasterException, xmlrpc.client.Error):
            pass
    return pids


def rss_mb(pid):
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    raise OSError("no VmRSS for %d" % pid)


def cpu_seconds(pid):
    with open("/proc/%d/stat" % pid) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK  # utime + stime


def alive(pid):
    try:
        os.kill(pid, 0)
        return True
    except OSError:
        return False


def rising_mb(samples):
    """Rise of the least-squares line through [(t, mb)] over its span."""
    if len(samples) < 3:
        return 0.0
    n = len(samples)
    mt = sum(t for t, _ in samples) / n
    mm = sum(m for _, m in samples) / n
    var = sum((t - mt) ** 2 for t, _ in samples)
    slope = sum((t - mt) * (m - mm) for t, m in samples) / var if var > 0 else 0.0
    return slope * (samples[-1][0] - samples[0][0])


def main():
    if len(sys.argv) < 6:
        sys.exit(__doc__)
    ns, minutes, sample_s, warmup_min, csv_path = sys.argv[1].rstrip("/"), float(sys.argv[2]), float(sys.argv[3]), \
        float(sys.argv[4]), sys.argv[5]
    tolerance_mb = float(sys.argv[6]) if len(sys.argv) > 6 else 32.0
    rospy.init_node("soak_monitor", anonymous=True, disable_signals=True)
    cloud_points = [0]
    rospy.Subscriber(ns + "/cloud", PointCloud2, lambda m: cloud_points.__setitem__(0, m.width * m.height), queue_size=1)
    stats = rospy.ServiceProxy(ns + "/inference/stats", Trigger)
    stats.wait_for_service(timeout=300)
    pids = node_pids(ns)
    if not pids:
        sys.exit("soak_monitor: no node under %s" % ns)
    print("soak_monitor: watching %s" % ", ".join("%s (pid %d)" % kv for kv in sorted(pids.items())), flush=True)

    start = time.monotonic()
    last_cpu = {name: (start, cpu_seconds(pid)) for name, pid in pids.items()}
    rss = {name: [] for name in pids}
    counts, problems = [], []
    with open(csv_path, "w", newline="") as out:
        table = csv.writer(out)
        table.writerow(["minute", "node", "pid", "rss_mb", "cpu_percent", "sets_processed", "sets_dropped",
                        "sets_failed", "cloud_points"])
        while not problems:
            time.sleep(max(0.0, start + (len(counts) + 1) * sample_s - time.monotonic()))
            now = time.monotonic()
            minute = (now - start) / 60.0
            try:
                m = STATS.search(stats().message)
                counts.append((minute, int(m.group(1)), int(m.group(2)), int(m.group(3))))
            except (rospy.ServiceException, AttributeError) as e:
                problems.append("inference's stats did not answer at minute %.1f: %s" % (minute, e))
                break
            current = node_pids(ns)
            for name, pid in sorted(pids.items()):
                if not alive(pid) or current.get(name) != pid:
                    problems.append("%s (pid %d) died or was restarted at minute %.1f" % (name, pid, minute))
                    continue
                mb, cpu = rss_mb(pid), cpu_seconds(pid)
                t0, c0 = last_cpu[name]
                last_cpu[name] = (now, cpu)
                rss[name].append((minute, mb))
                table.writerow([round(minute, 2), name, pid, round(mb, 1), round(100.0 * (cpu - c0) / (now - t0), 1)]
                               + list(counts[-1][1:]) + [cloud_points[0]])
            out.flush()
            print("soak_monitor: minute %.1f: %s; sets processed %d, dropped %d, failed %d; cloud %d points" % (
                minute, ", ".join("%s %.0f MB" % (n.rsplit("/", 1)[1], v[-1][1]) for n, v in sorted(rss.items()) if v),
                counts[-1][1], counts[-1][2], counts[-1][3], cloud_points[0]), flush=True)
            if minute >= minutes - 1e-6:
                break

    after = [c for c in counts if c[0] >= warmup_min]
    if counts and counts[-1][3] > 0:
        problems.append("%d keyframe sets failed" % counts[-1][3])
    if len(after) >= 2 and after[-1][1] <= after[0][1]:
        problems.append("no keyframe set was processed after the warm-up")
    print("\nnode                                  RSS after warm-up (MB)   line's rise (MB)   limit (MB)")
    for name, samples in sorted(rss.items()):
        warm = [s for s in samples if s[0] >= warmup_min]
        if not warm:
            continue
        rise = rising_mb(warm)
        limit = max(tolerance_mb, 0.05 * warm[0][1])
        print("%-37s %7.0f .. %-7.0f        %+8.1f          %6.1f" % (name, min(m for _, m in warm), max(m for _, m in warm),
                                                                     rise, limit))
        if rise > limit:
            problems.append("%s kept growing after the warm-up: %+.1f MB over %.0f min" % (name, rise,
                                                                                        warm[-1][0] - warm[0][0]))
    if counts:
        print("keyframe sets over %.0f min: %d processed, %d dropped (stale), %d failed" % (counts[-1][0], *counts[-1][1:]))
    for p in problems:
        print("FAIL: " + p)
    print("soak: " + ("FAILED" if problems else "passed") + " (samples: %s)" % csv_path)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
