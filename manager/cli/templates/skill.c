/* @NAME@: slows down and turns away from what is near ahead (reads the sonar ring, proposes
 * on the `drive` channel; arbitrated with wander and avoid by priority). */
#include <math.h>
#include <stdio.h>
#include "skillfab.h"

static int IN_SONAR, OUT_DRIVE, P_NEAR;

static int32_t compute(sf_run *run, void *user) {
    (void)user;
    const sf_Sonar *sonar = sf_input(run, IN_SONAR, sizeof *sonar);
    if (!sonar) return 1;
    double near = sf_param_float(run, P_NEAR), ahead = INFINITY;
    const int look[3] = {0, 1, 23}; /* the sonars that look ahead; NaN counts as far */
    for (int k = 0; k < 3; k++)
        if (sonar->range[look[k]] < ahead) ahead = sonar->range[look[k]];
    if (!(ahead < near)) return 0; /* nothing near: no proposal */
    sf_Drive *cmd = sf_output(run, OUT_DRIVE, sizeof *cmd);
    if (!cmd) return 1;
    cmd->translate = 0.1 * ahead / near;
    cmd->rotate = 0.5;
    return 0;
}

int main(int argc, char **argv) {
    sf_skill *s = sf_skill_new("@NAME@", SF_SYNC);
    if (!s || (IN_SONAR = sf_skill_input(s, "sonar", SF_SONAR_TYPE_NAME)) < 0
        || (OUT_DRIVE = sf_skill_proposal(s, "drive", SF_DRIVE_TYPE_NAME)) < 0
        || (P_NEAR = sf_skill_param_float(s, "near", 1.2, 0.1, 5.0,
                                          "Closer than this ahead (m), it slows and turns.")) < 0
        || sf_skill_priority(s, 5) < 0 || sf_skill_compute(s, compute, NULL) < 0) {
        fprintf(stderr, "@NAME@: %s\n", sf_last_error());
        sf_skill_free(s);
        return 1;
    }
    return sf_skill_run(s, argc, (const char *const *)argv);
}
