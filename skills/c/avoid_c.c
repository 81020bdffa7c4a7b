/* avoid_c: a classic obstacle-avoidance routine in C, as the paper's users brought theirs —
 * the repulsive potential field of Khatib (1986) / Arkin's avoid-static-obstacle schema over
 * the Denning sonar ring, proposing a drive command on the `drive` actuator channel.
 *
 * Every sonar i closer than `safe_distance` pushes the robot away from its bearing with a
 * strength growing linearly to 1 at contact; the sum's forward component slows (or backs)
 * the robot, its lateral component turns it away. Nothing near: no proposal, so a lower
 * priority skill (wander, a sequencer's goal) drives.
 */
#include <math.h>
#include <stdio.h>
#include "skillfab.h"

static int IN_SONAR, OUT_DRIVE, P_SAFE, P_SPEED, P_TURN;

static int32_t compute(sf_run *run, void *user) {
    (void)user;
    const sf_Sonar *sonar = sf_input(run, IN_SONAR, sizeof *sonar);
    if (!sonar) return 1;
    double safe = sf_param_float(run, P_SAFE);
    double fx = 0.0, fy = 0.0;
    int near = 0;
    for (int i = 0; i < (int)(sizeof sonar->range / sizeof sonar->range[0]); i++) {
        double r = sonar->range[i];
        if (!(r < safe)) continue; /* far, no echo (inf) or never read (NaN) */
        double bearing = i * (2.0 * M_PI / 24.0);
        double push = (safe - r) / safe;
        fx -= push * cos(bearing);
        fy -= push * sin(bearing);
        near = 1;
    }
    if (!near) return 0; /* no proposal this cycle */
    sf_Drive *cmd = sf_output(run, OUT_DRIVE, sizeof *cmd);
    if (!cmd) return 1;
    double speed = sf_param_float(run, P_SPEED);
    /* Forward motion only when the push does not oppose it; turn away from the push. */
    cmd->translate = fx >= 0.0 ? speed * fmin(1.0, fx) : fmax(-speed, speed * fx);
    cmd->rotate = sf_param_float(run, P_TURN) * atan2(fy, fabs(fx) + 1e-9);
    return 0;
}

int main(int argc, char **argv) {
    sf_skill *s = sf_skill_new("avoid_c", SF_SYNC);
    if (!s
        || (IN_SONAR = sf_skill_input(s, "sonar", SF_SONAR_TYPE_NAME)) < 0
        || (OUT_DRIVE = sf_skill_proposal(s, "drive", SF_DRIVE_TYPE_NAME)) < 0
        || (P_SAFE = sf_skill_param_float(s, "safe_distance", 0.6, 0.05, 5.0,
                                          "Obstacles nearer than this (m) push the robot away.")) < 0
        || (P_SPEED = sf_skill_param_float(s, "speed", 0.3, 0.0, 1.0,
                                           "Largest translate speed it commands (m/s).")) < 0
        || (P_TURN = sf_skill_param_float(s, "turn_gain", 1.0, 0.0, 5.0,
                                          "Rotate speed (rad/s) per radian of push direction.")) < 0
        || sf_skill_priority(s, 10) < 0
        || sf_skill_compute(s, compute, NULL) < 0) {
        fprintf(stderr, "avoid_c: %s\n", sf_last_error());
        sf_skill_free(s);
        return 1;
    }
    return sf_skill_run(s, argc, (const char *const *)argv);
}
