// smooth_cpp: an exponential moving average in C++ over the C ABI's RAII layer
// (skillfab.hpp). Sync: one sample folded in per cycle, so its output is exactly reproducible
// (the polyglot network checks it against a reference every cycle).
#include <cstdio>
#include <optional>

#include "skillfab.hpp"

int main(int argc, char **argv) try {
    skillfab::Skill s("smooth_cpp");
    auto in = s.input<sf_Scaled>("scaled", SF_SCALED_TYPE_NAME);
    auto out = s.output<sf_Smoothed>("smoothed", SF_SMOOTHED_TYPE_NAME);
    auto alpha = s.param_float("alpha", 0.1, 0.0, 1.0, "Weight of the newest sample.");
    std::optional<sf_Smoothed> state;
    return s.run(argc, argv, [&](skillfab::Run &r) {
        double x = r.input(in).value;
        double a = r.param_float(alpha);
        state = state ? sf_Smoothed{a * x + (1.0 - a) * state->value, state->samples + 1}
                      : sf_Smoothed{x, 1};
        r.output(out) = *state;
    });
} catch (const skillfab::Error &e) {
    std::fprintf(stderr, "smooth_cpp: %s\n", e.what());
    return 1;
}
