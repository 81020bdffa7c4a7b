// @NAME@: slows down and turns away from what is near ahead (reads the sonar ring, proposes
// on the `drive` channel; arbitrated with wander and avoid by priority).
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "skillfab.hpp"

int main(int argc, char **argv) try {
    skillfab::Skill s("@NAME@");
    auto sonar = s.input<sf_Sonar>("sonar", SF_SONAR_TYPE_NAME);
    auto drive = s.proposal<sf_Drive>("drive", SF_DRIVE_TYPE_NAME);
    auto near = s.param_float("near", 1.2, 0.1, 5.0, "Closer than this ahead (m), it slows and turns.");
    s.priority(5);
    return s.run(argc, argv, [&](skillfab::Run &r) {
        const sf_Sonar &ring = r.input(sonar);
        double ahead = INFINITY;
        for (int k : {0, 1, 23}) // the sonars that look ahead; NaN counts as far
            if (ring.range[k] < ahead) ahead = ring.range[k];
        double n = r.param_float(near);
        if (ahead < n) r.output(drive) = sf_Drive{0.1 * ahead / n, 0.5};
    });
} catch (const skillfab::Error &e) {
    std::fprintf(stderr, "@NAME@: %s\n", e.what());
    return 1;
}
