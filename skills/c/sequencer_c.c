/* sequencer_c: a sequencer in C driving the hello network (skills/launch/hello.toml) through
 * libskillfab's client: set a parameter, read it back, query an output, wait for a monitor's
 * event, deactivate and reactivate a skill, want a skill (its producer comes with it) and
 * release it. Exits 0 when every step did what it should.
 *
 *   target/debug/skillfab up skills/launch/hello.toml &   then   target/debug/sequencer_c
 */
#include <stdio.h>
#include <string.h>
#include "skillfab.h"

#define TRY(call)                                                               \
    do {                                                                        \
        if ((call) < 0) {                                                       \
            fprintf(stderr, "sequencer_c: %s: %s\n", #call, sf_last_error());   \
            return 1;                                                           \
        }                                                                       \
    } while (0)

int main(int argc, char **argv) {
    sf_client *c = sf_client_connect(argc > 1 ? argv[1] : NULL);
    if (!c) {
        fprintf(stderr, "sequencer_c: %s\n", sf_last_error());
        return 1;
    }
    char buf[4096];

    TRY(sf_client_set_param(c, "scale", "gain", "3"));
    TRY(sf_client_get_param(c, "scale", "gain", buf, sizeof buf));
    printf("scale.gain = %s\n", buf);

    /* A refused request is an error with a reason, not a crash. */
    if (sf_client_set_param(c, "scale", "gain", "lots") >= 0) return 1;
    printf("refused: %s\n", sf_last_error());

    /* Monitor: fires once, the first cycle the scaled value (3 × tick) is above 30. */
    TRY(sf_client_query(c, "scale.scaled.value", buf, sizeof buf));
    printf("scale.scaled = %s\n", buf);
    int64_t id = sf_client_add_monitor(c, "scale.scaled.value > 30", SF_MONITOR_ONCE, 0);
    TRY(id);
    int fired = 0;
    for (int i = 0; i < 100 && !fired; i++) {
        int rc = sf_client_next_event(c, 100, buf, sizeof buf);
        TRY(rc);
        if (rc == 1 && strstr(buf, "\"monitor_fired\"")) {
            printf("event: %s\n", buf);
            fired = 1;
        }
    }
    if (!fired) {
        fprintf(stderr, "sequencer_c: the monitor never fired\n");
        return 1;
    }

    TRY(sf_client_deactivate(c, "smooth"));
    TRY(sf_client_activate(c, "smooth"));
    printf("smooth deactivated and activated again\n");

    /* Demand: smooth reads what scale writes, so wanting smooth brings scale back, and
     * releasing smooth deactivates both. A skill nobody knows is refused. */
    TRY(sf_client_deactivate(c, "smooth"));
    TRY(sf_client_deactivate(c, "scale"));
    TRY(sf_client_want(c, "smooth"));
    static char list[1 << 16];
    TRY(sf_client_list(c, list, sizeof list));
    const char *scale = strstr(list, "\"name\":\"scale\"");
    const char *state = scale ? strstr(scale, "\"state\":\"") : NULL;
    if (!state || strncmp(state + 9, "active\"", 7) != 0) {
        fprintf(stderr, "sequencer_c: scale is not active after want smooth: %s\n", list);
        return 1;
    }
    TRY(sf_client_release(c, "smooth"));
    if (sf_client_want(c, "ghost") >= 0) return 1;
    printf("want refused: %s\n", sf_last_error());
    TRY(sf_client_activate(c, "scale"));
    TRY(sf_client_activate(c, "smooth"));
    printf("wanted smooth with scale, released both\n");
    sf_client_free(c);
    printf("ok\n");
    return 0;
}
