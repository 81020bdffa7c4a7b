#!/usr/bin/env python3
"""smooth_py: an exponential moving average as a Python skill (ctypes over libskillfab).

Sync: one sample folded in per cycle, so its output is exactly reproducible (the polyglot
network checks it against a reference every cycle). Run it like any skill:
    skills/python/smooth_py.py --name smooth_py --param alpha=0.2
"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "python"))
import skillfab  # noqa: E402
from skillfab.msgs import Scaled, Smoothed  # noqa: E402


class SmoothPy(skillfab.Skill):
    inputs = {"scaled": Scaled}
    outputs = {"smoothed": Smoothed}
    params = {"alpha": skillfab.Param(0.1, min=0.0, max=1.0, doc="Weight of the newest sample.")}

    def __init__(self):
        self.state = None

    def compute(self, run, i, o):
        x, a = i.scaled.value, run.params.alpha
        if self.state is None:
            self.state = (x, 1)
        else:
            self.state = (a * x + (1.0 - a) * self.state[0], self.state[1] + 1)
        o.smoothed.value, o.smoothed.samples = self.state


if __name__ == "__main__":
    skillfab.main(SmoothPy)
