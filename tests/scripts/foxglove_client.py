"""A client of the Foxglove WebSocket protocol (foxglove.websocket.v1), written from the
protocol's published description (foxglove/ws-protocol, docs/spec.md) — not from skillfab's
server — to check `skillfab view` from the outside.

    python3 foxglove_client.py ws://127.0.0.1:PORT

It subscribes to the sonar, odometry and plan channels and decodes what arrives (CDR through
mcap-ros2-support's decoder built from the advertised ros2msg schema; JSON for the plan), sets
a parameter and reads it back, sends bad input and expects error statuses while the connection
goes on, then calls the activate service for `wander`. It prints one JSON object (what it saw)
and exits 0, or raises.
"""

import json
import math
import struct
import sys
import time

from mcap_ros2._dynamic import generate_dynamic
from websockets.sync.client import connect

URL = sys.argv[1]
SUBPROTOCOL = "foxglove.websocket.v1"
report = {}


class Conn:
    def __init__(self, ws):
        self.ws = ws
        assert self.ws.subprotocol == SUBPROTOCOL, self.ws.subprotocol
        self.texts = []  # JSON messages not consumed yet
        self.data = []  # (subscription id, timestamp, payload)
        self.responses = []  # (service id, call id, encoding, payload)
        self.channels = {}
        self.services = {}

    def pump(self, timeout):
        """Reads what arrives for at most `timeout` seconds."""
        end = time.monotonic() + timeout
        while True:
            left = end - time.monotonic()
            if left <= 0:
                return
            try:
                m = self.ws.recv(timeout=left)
            except TimeoutError:
                return
            if isinstance(m, str):
                j = json.loads(m)
                if j["op"] == "advertise":
                    for c in j["channels"]:
                        self.channels[c["id"]] = c
                elif j["op"] == "advertiseServices":
                    for s in j["services"]:
                        self.services[s["name"]] = s
                self.texts.append(j)
            else:
                op = m[0]
                if op == 0x01:
                    sub, ts = struct.unpack_from("<IQ", m, 1)
                    self.data.append((sub, ts, m[13:]))
                elif op == 0x03:
                    sid, cid, n = struct.unpack_from("<III", m, 1)
                    self.responses.append((sid, cid, m[13 : 13 + n].decode(), m[13 + n :]))
                else:
                    raise AssertionError(f"unknown binary opcode {op:#x}")

    def wait_text(self, pred, what, timeout=10):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            for i, j in enumerate(self.texts):
                if pred(j):
                    return self.texts.pop(i)
            self.pump(0.1)
        raise AssertionError(f"no {what} within {timeout} s; texts: {self.texts[-5:]}")

    def send(self, obj):
        self.ws.send(json.dumps(obj))


ws = connect(URL, subprotocols=[SUBPROTOCOL], max_size=None, open_timeout=10)
c = Conn(ws.__enter__())
info = c.wait_text(lambda j: j["op"] == "serverInfo", "serverInfo")
for cap in ("parameters", "services"):
    assert cap in info["capabilities"], info
# Channels of the fabric come as its skills register: wait for the sonar and odometry.
by_schema = {}
end = time.monotonic() + 20
while time.monotonic() < end:
    c.pump(0.2)
    by_schema = {ch["schemaName"]: ch for ch in c.channels.values()}
    if "skillfab/msg/Sonar" in by_schema and "skillfab/msg/Odometry" in by_schema:
        break
sonar, odom = by_schema["skillfab/msg/Sonar"], by_schema["skillfab/msg/Odometry"]
plan = next(ch for ch in c.channels.values() if ch["topic"] == "/plan")
for ch in (sonar, odom):
    assert ch["encoding"] == "cdr" and ch["schemaEncoding"] == "ros2msg", ch
report["channels"] = sorted(ch["topic"] for ch in c.channels.values())

# Subscribe (ids of our choosing) and decode.
subs = {10: sonar, 11: odom, 12: plan}
c.send({"op": "subscribe", "subscriptions": [{"id": i, "channelId": ch["id"]} for i, ch in subs.items()]})
decoders = {
    i: generate_dynamic(ch["schemaName"], ch["schema"])[ch["schemaName"]]
    for i, ch in subs.items()
    if ch["encoding"] == "cdr"
}
got = {i: [] for i in subs}
end = time.monotonic() + 20
while time.monotonic() < end and (len(got[10]) < 5 or len(got[11]) < 5 or not got[12]):
    c.pump(0.2)
    for sub, ts, payload in c.data:
        assert sub in subs, f"data for subscription {sub} never made"
        got[sub].append(decoders[sub](payload) if sub in decoders else json.loads(payload))
    c.data.clear()
assert len(got[10]) >= 5 and len(got[11]) >= 5 and got[12], {k: len(v) for k, v in got.items()}
ring = got[10][-1].range
assert len(ring) == 24, ring
echoes = [r for r in ring if math.isfinite(r)]
assert echoes and all(0.0 < r <= 10.5 for r in echoes), ring
pose = got[11][-1]
assert all(math.isfinite(v) for v in (pose.x, pose.y, pose.theta)), pose
tree = got[12][-1]
running = [n for n in tree["nodes"] if n["status"] == "running"]
assert running, tree
report["sonar"] = {"samples": len(got[10]), "echoes": len(echoes), "nearest": min(echoes)}
report["odometry"] = {"samples": len(got[11]), "x": pose.x, "y": pose.y}
report["plan"] = {"plan": tree["plan"], "running": [n["name"] or n["kind"] for n in running]}

# Parameters: set one and see it applied.
c.send({"op": "setParameters", "id": "set-1", "parameters": [{"name": "/avoid/safe_distance", "value": 0.45}]})
vals = c.wait_text(lambda j: j["op"] == "parameterValues" and j.get("id") == "set-1", "set answer")
assert [p["value"] for p in vals["parameters"] if p["name"] == "/avoid/safe_distance"] == [0.45], vals
c.send({"op": "getParameters", "id": "get-1", "parameterNames": ["/avoid/safe_distance"]})
vals = c.wait_text(lambda j: j.get("id") == "get-1" and j["op"] == "parameterValues", "get answer")
assert vals["parameters"][0]["value"] == 0.45, vals
report["param"] = vals["parameters"][0]

# Bad input: each gets an error status, and the connection goes on.
def refused(msg, needle, send=None):
    (send or c.send)(msg)
    s = c.wait_text(lambda j: j["op"] == "status" and j["level"] == 2, f"error status for {msg!r}")
    assert needle in s["message"], (needle, s)
    return s["message"]


report["refusals"] = [
    refused({"op": "setParameters", "id": "bad-1", "parameters": [{"name": "/avoid/safe_distance", "value": 99.0}]}, "safe_distance"),
    refused({"op": "setParameters", "parameters": [{"name": "/avoid/safe_distance", "value": "far"}]}, "float"),
    refused({"op": "setParameters", "parameters": [{"name": "/nobody/x", "value": 1}]}, "/nobody/x"),
    refused({"op": "subscribe", "subscriptions": [{"id": 99, "channelId": 987654}]}, "987654"),
    refused({"op": "fly"}, "fly"),
    refused(None, "not understood", send=lambda _m: c.ws.send("garbage{")),
    refused(None, "0x07", send=lambda _m: c.ws.send(b"\x07\x00")),
]
# The refused set left the value as it was.
c.send({"op": "getParameters", "id": "get-2", "parameterNames": ["/avoid/safe_distance"]})
vals = c.wait_text(lambda j: j.get("id") == "get-2" and j["op"] == "parameterValues", "get answer")
assert vals["parameters"][0]["value"] == 0.45, vals

# A service call: activate wander.
svc = c.services["/skillfab/activate"]
body = json.dumps({"skills": ["wander"]}).encode()
c.ws.send(struct.pack("<BIII", 0x02, svc["id"], 7, 4) + b"json" + body)
end = time.monotonic() + 10
while time.monotonic() < end and not c.responses:
    c.pump(0.1)
assert c.responses, "no service call response"
sid, cid, enc, payload = c.responses[0]
assert (sid, cid, enc) == (svc["id"], 7, "json"), c.responses[0]
report["activate"] = json.loads(payload)
assert report["activate"]["ok"] is True, report
# A call with a bad request fails with a message.
c.ws.send(struct.pack("<BIII", 0x02, svc["id"], 8, 4) + b"json" + b"{}")
fail = c.wait_text(lambda j: j["op"] == "serviceCallFailure", "service call failure")
assert fail["callId"] == 8 and "skills" in fail["message"], fail
ws.__exit__(None, None, None)
print(json.dumps(report))
