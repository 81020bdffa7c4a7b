/* scale_c: the hello network's `scale` in C — scaled = gain × tick.
 *
 * Build (after `cargo build`): make -C skills          (see skills/Makefile)
 * Run:   target/debug/scale_c --name scale_c --param gain=3
 */
#include <stdio.h>
#include "skillfab.h"

static int IN_TICK, OUT_SCALED, P_GAIN;

static int32_t compute(sf_run *run, void *user) {
    (void)user;
    const sf_Tick *tick = sf_input(run, IN_TICK, sizeof *tick);
    sf_Scaled *out = sf_output(run, OUT_SCALED, sizeof *out);
    if (!tick || !out) return 1; /* sf_last_error() says why; the run fails, nothing is sent */
    out->value = sf_param_float(run, P_GAIN) * (double)tick->value;
    return 0;
}

int main(int argc, char **argv) {
    sf_skill *s = sf_skill_new("scale_c", SF_SYNC);
    if (!s
        || (IN_TICK = sf_skill_input(s, "tick", SF_TICK_TYPE_NAME)) < 0
        || (OUT_SCALED = sf_skill_output(s, "scaled", SF_SCALED_TYPE_NAME)) < 0
        || (P_GAIN = sf_skill_param_float(s, "gain", 2.0, -1e6, 1e6, "Factor applied to the tick.")) < 0
        || sf_skill_compute(s, compute, NULL) < 0) {
        fprintf(stderr, "scale_c: %s\n", sf_last_error());
        sf_skill_free(s);
        return 1;
    }
    return sf_skill_run(s, argc, (const char *const *)argv);
}
