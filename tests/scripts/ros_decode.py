"""Reads a skillfab recording with the ROS tools' Python packages, as a ROS user would.

    python3 ros_decode.py RUN.mcap

Every message is decoded: `cdr` channels through mcap_ros2's DecoderFactory (their ros2msg
schemas), `json` channels through json.loads. Fails (exit status 1, the reason on stderr) if
a message does not decode, if the count differs from the summary's, or if the sonar and
odometry samples do not read as a robot's; prints what it read as one JSON object.
"""

import json
import math
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def fail(why):
    print(f"ros_decode: {why}", file=sys.stderr)
    sys.exit(1)


def main(path):
    factory = DecoderFactory()
    counts = {"cdr": 0, "json": 0}
    per_channel = {}
    sonar_ranges = []
    poses = []
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is None or summary.statistics is None:
            fail("no summary with statistics")
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            enc = channel.message_encoding
            if enc == "cdr":
                decode = factory.decoder_for(enc, schema)
                if decode is None:
                    fail(f"{channel.topic}: no ROS 2 decoder for schema {schema and schema.name}")
                value = decode(message.data)
                if schema.name == "skillfab/msg/Sonar":
                    if len(value.range) != 24 or len(value.age_ms) != 24:
                        fail(f"{channel.topic}: a sonar ring of {len(value.range)}")
                    sonar_ranges.extend(r for r in value.range if math.isfinite(r))
                elif schema.name == "skillfab/msg/Odometry":
                    poses.append((value.x, value.y, value.theta))
            elif enc == "json":
                value = json.loads(message.data)
                if not isinstance(value, dict) or "kind" not in value:
                    fail(f"{channel.topic}: a JSON record without its kind: {value!r}")
            else:
                fail(f"{channel.topic}: message encoding {enc!r}")
            counts[enc] += 1
            per_channel[channel.id] = per_channel.get(channel.id, 0) + 1
    total = counts["cdr"] + counts["json"]
    if total != summary.statistics.message_count:
        fail(f"{total} messages read, the summary counts {summary.statistics.message_count}")
    if per_channel != dict(summary.statistics.channel_message_counts):
        fail("messages per channel differ from the summary's")
    if not sonar_ranges or not poses:
        fail(f"{len(sonar_ranges)} sonar ranges, {len(poses)} odometry samples")
    for x, y, theta in poses:
        if not all(math.isfinite(v) for v in (x, y, theta)) or abs(x) > 100 or abs(y) > 100:
            fail(f"an odometry sample off the map: {(x, y, theta)}")
    moved = max(math.hypot(x - poses[0][0], y - poses[0][1]) for x, y, _ in poses)
    print(
        json.dumps(
            {
                "messages": total,
                "summary_messages": summary.statistics.message_count,
                "cdr": counts["cdr"],
                "json": counts["json"],
                "sonar_min": min(sonar_ranges),
                "sonar_max": max(sonar_ranges),
                "odometry": len(poses),
                "moved_m": moved,
            }
        )
    )


if __name__ == "__main__":
    if len(sys.argv) != 2:
        fail("usage: ros_decode.py RUN.mcap")
    main(sys.argv[1])
