#!/usr/bin/env python3
"""@NAME@: slows down and turns away from what is near ahead (reads the sonar ring, proposes on
the `drive` channel; arbitrated with wander and avoid by priority)."""
import math

import skillfab
from skillfab.msgs import Drive, Sonar


class Skill(skillfab.Skill):
    inputs = {"sonar": Sonar}
    proposals = {"drive": Drive}
    params = {"near": skillfab.Param(1.2, min=0.1, max=5.0, doc="Closer than this ahead (m), it slows and turns.")}
    priority = 5

    def compute(self, run, i, o):
        # The sonars that look ahead; NaN (never read) counts as far.
        ahead = min((r for r in (i.sonar.range[0], i.sonar.range[1], i.sonar.range[23]) if not math.isnan(r)), default=math.inf)
        if ahead < run.params.near:
            o.drive.translate = 0.1 * ahead / run.params.near
            o.drive.rotate = 0.5


if __name__ == "__main__":
    skillfab.main(Skill)
