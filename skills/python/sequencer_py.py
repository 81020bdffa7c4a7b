#!/usr/bin/env python3
"""sequencer_py: a sequencer in Python driving the hello network (skills/launch/hello.toml):
set and read a parameter, query an output, wait for a monitor's event, deactivate and
reactivate a skill, want a skill (its producer comes with it) and release it. Exits 0 when every step did what it should.

    target/debug/skillfab up skills/launch/hello.toml &
    skills/python/sequencer_py.py [DOMAIN]
"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "python"))
import skillfab  # noqa: E402


def main():
    with skillfab.Client(sys.argv[1] if len(sys.argv) > 1 else None) as c:
        print("skills:", ", ".join(s["name"] for s in c.skills()))
        c.set_param("scale", "gain", 3)
        assert c.get_param("scale", "gain") == 3.0
        print("scale.gain =", c.get_param("scale", "gain"))
        try:
            c.set_param("scale", "gain", "lots")
            raise SystemExit("a bad value was accepted")
        except skillfab.FabricError as e:
            print("refused:", e)
        value, cycle = c.query("scale.scaled.value")
        print(f"scale.scaled.value = {value} (cycle {cycle})")
        c.monitor(f"scale.scaled.value > {value + 30}")
        while True:
            ev = c.next_event(timeout=5.0)
            if ev is None:
                raise SystemExit("the monitor never fired")
            if ev["event"] == "monitor_fired":
                print("event:", ev)
                break
        c.deactivate("smooth")
        c.activate("smooth")
        print("smooth deactivated and activated again")
        # Demand: smooth reads what scale writes, so wanting smooth brings scale back.
        c.deactivate("smooth")
        c.deactivate("scale")
        c.want("smooth")
        state = {s["name"]: s["state"] for s in c.skills()}
        assert state["smooth"] == "active" and state["scale"] == "active", state
        c.release("smooth")
        state = {s["name"]: s["state"] for s in c.skills()}
        assert state["smooth"] == "inactive" and state["scale"] == "inactive", state
        print("wanted smooth with scale, released both")
        c.activate("scale")
        c.activate("smooth")
    print("ok")


if __name__ == "__main__":
    main()
