// skillfab.hpp: a thin C++17 layer over libskillfab's C ABI (skillfab.h) — RAII ownership,
// exceptions for errors, typed ports, and a body that is any callable.
//
//   skillfab::Skill s("smooth_cpp");
//   auto in = s.input<sf_Scaled>("scaled", SF_SCALED_TYPE_NAME);
//   auto out = s.output<sf_Smoothed>("smoothed", SF_SMOOTHED_TYPE_NAME);
//   auto alpha = s.param_float("alpha", 0.1, 0.0, 1.0, "Weight of the newest sample.");
//   return s.run(argc, argv, [&](skillfab::Run &r) { r.output(out).value = r.input(in).value; });
//
// Exceptions never cross into the library: a body that throws fails its run (logged, outputs
// not sent) and the skill goes on with the next cycle.
#ifndef SKILLFAB_HPP
#define SKILLFAB_HPP

#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>
#include <utility>

#include "skillfab.h"

namespace skillfab {

/// An error of the C ABI: its code and message.
class Error : public std::runtime_error {
public:
    Error(int code, const std::string &what) : std::runtime_error(what), code_(code) {}
    int code() const noexcept { return code_; }

private:
    int code_;
};

/// Throws the thread's last error if `rc` is negative; returns `rc`.
inline int64_t check(int64_t rc) {
    if (rc < 0) throw Error(static_cast<int>(rc), sf_last_error());
    return rc;
}

/// A typed input or output index.
template <class T> struct Port { int index; };
/// A parameter index.
struct Param { int index; };

/// One run, as the body sees it.
class Run {
public:
    explicit Run(sf_run *r) : r_(r) {}
    /// The input's message (throws if there is none this run).
    template <class T> const T &input(Port<T> p) const {
        auto v = static_cast<const T *>(sf_input(r_, p.index, sizeof(T)));
        if (!v) throw Error(SF_ERR_INDEX, sf_last_error());
        return *v;
    }
    /// The output's message to fill (zeroed; marks it written).
    template <class T> T &output(Port<T> p) {
        auto v = static_cast<T *>(sf_output(r_, p.index, sizeof(T)));
        if (!v) throw Error(SF_ERR_INDEX, sf_last_error());
        return *v;
    }
    double param_float(Param p) const { return sf_param_float(r_, p.index); }
    int64_t param_int(Param p) const { return sf_param_int(r_, p.index); }
    bool param_bool(Param p) const { return sf_param_bool(r_, p.index); }
    uint64_t cycle() const { return sf_run_cycle(r_); }

private:
    sf_run *r_;
};

/// A skill: declare ports and parameters, then `run` it with a body.
class Skill {
public:
    explicit Skill(const char *kind, int mode = SF_SYNC) : s_(sf_skill_new(kind, mode)) {
        if (!s_) throw Error(SF_ERR_INVALID, sf_last_error());
    }
    ~Skill() { sf_skill_free(s_); }
    Skill(const Skill &) = delete;
    Skill &operator=(const Skill &) = delete;

    template <class T> Port<T> input(const char *port, const char *type_name) {
        return Port<T>{static_cast<int>(check(sf_skill_input(s_, port, type_name)))};
    }
    template <class T> Port<T> output(const char *port, const char *type_name) {
        return Port<T>{static_cast<int>(check(sf_skill_output(s_, port, type_name)))};
    }
    template <class T> Port<T> proposal(const char *channel, const char *type_name) {
        return Port<T>{static_cast<int>(check(sf_skill_proposal(s_, channel, type_name)))};
    }
    Param param_float(const char *name, double def, double min, double max, const char *doc = "") {
        return Param{static_cast<int>(check(sf_skill_param_float(s_, name, def, min, max, doc)))};
    }
    Param param_int(const char *name, int64_t def, int64_t min, int64_t max, const char *doc = "") {
        return Param{static_cast<int>(check(sf_skill_param_int(s_, name, def, min, max, doc)))};
    }
    Param param_bool(const char *name, bool def, const char *doc = "") {
        return Param{static_cast<int>(check(sf_skill_param_bool(s_, name, def, doc)))};
    }
    void priority(int p) { check(sf_skill_priority(s_, p)); }

    /// Serves cycles with `body` until SIGINT/SIGTERM; returns the process exit code.
    int run(int argc, char **argv, std::function<void(Run &)> body) {
        body_ = std::move(body);
        check(sf_skill_compute(s_, &Skill::trampoline, this));
        sf_skill *s = std::exchange(s_, nullptr); // sf_skill_run frees it
        return sf_skill_run(s, argc, const_cast<const char *const *>(argv));
    }

private:
    static int32_t trampoline(sf_run *r, void *self) noexcept {
        Run run(r);
        try {
            static_cast<Skill *>(self)->body_(run);
            return 0;
        } catch (const std::exception &e) {
            sf_run_fail(r, e.what());
        } catch (...) {
            sf_run_fail(r, "unknown C++ exception");
        }
        return 1;
    }

    sf_skill *s_;
    std::function<void(Run &)> body_;
};

/// A sequencer's connection to a domain's manager.
class Client {
public:
    explicit Client(const char *domain = nullptr) : c_(sf_client_connect(domain)) {
        if (!c_) throw Error(SF_ERR_FABRIC, sf_last_error());
    }
    ~Client() { sf_client_free(c_); }
    Client(const Client &) = delete;
    Client &operator=(const Client &) = delete;

    void activate(const char *skill) { check(sf_client_activate(c_, skill)); }
    void deactivate(const char *skill) { check(sf_client_deactivate(c_, skill)); }
    /// Activates `skill` with every skill it reads from, transitively.
    void want(const char *skill) { check(sf_client_want(c_, skill)); }
    /// Deactivates a wanted skill and what was activated only for it.
    void release(const char *skill) { check(sf_client_release(c_, skill)); }
    void set_param(const char *skill, const char *param, const char *value) {
        check(sf_client_set_param(c_, skill, param, value));
    }
    /// The latest value at `path` as JSON text `{"value": ..., "cycle": n}`.
    std::string query(const char *path) {
        std::string buf(4096, '\0');
        check(sf_client_query(c_, path, buf.data(), buf.size()));
        return buf.c_str();
    }
    int64_t add_monitor(const char *expr, int mode = SF_MONITOR_ONCE, uint32_t hold = 0) {
        return check(sf_client_add_monitor(c_, expr, mode, hold));
    }
    /// The next event as JSON text, or "" after `timeout_ms`.
    std::string next_event(uint32_t timeout_ms) {
        std::string buf(8192, '\0');
        return check(sf_client_next_event(c_, timeout_ms, buf.data(), buf.size())) ? buf.c_str() : "";
    }

private:
    sf_client *c_;
};

} // namespace skillfab

#endif // SKILLFAB_HPP
