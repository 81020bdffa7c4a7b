#!/usr/bin/env python3
"""scale_py: the hello network's `scale` in Python — scaled = gain × tick (the benchmark's
Python counterpart of skills/src/bin/scale.rs and skills/c/scale_c.c)."""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "python"))
import skillfab  # noqa: E402
from skillfab.msgs import Scaled, Tick  # noqa: E402


class ScalePy(skillfab.Skill):
    inputs = {"tick": Tick}
    outputs = {"scaled": Scaled}
    params = {"gain": skillfab.Param(2.0, min=-1e6, max=1e6, doc="Factor applied to the tick.")}

    def compute(self, run, i, o):
        o.scaled.value = run.params.gain * i.tick.value


if __name__ == "__main__":
    skillfab.main(ScalePy)
