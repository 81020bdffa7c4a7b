"""skillfab in Python: skills and sequencers over libskillfab's C ABI, with ctypes only.

A skill::

    import skillfab
    from skillfab.msgs import Scaled, Smoothed

    class SmoothPy(skillfab.Skill):
        inputs = {"scaled": Scaled}
        outputs = {"smoothed": Smoothed}
        params = {"alpha": skillfab.Param(0.1, min=0.0, max=1.0, doc="Weight of the newest sample.")}

        def compute(self, run, i, o):
            o.smoothed.value = run.params.alpha * i.scaled.value

    skillfab.main(SmoothPy)     # --name, --domain, --param ... as every skill

A sequencer::

    c = skillfab.Client()              # $SKILLFAB_DOMAIN or "default"
    c.set_param("scale", "gain", 3)
    c.monitor("scale.scaled.value > 30")
    event = c.next_event(timeout=1.0)  # a dict, as `skillfab ctl --json events` prints

The library is found at $SKILLFAB_LIB, next to the `skillfab` program that started this
process ($SKILLFAB_BIN_DIR, set by `skillfab up`), or in the repository's target/release or
target/debug.
"""

import ctypes
import json
import os
import sys

from . import msgs

__all__ = ["Skill", "Param", "Client", "FabricError", "main", "SYNC", "ASYNC", "lib"]

SYNC, ASYNC = 0, 1
MONITOR_MODES = {"once": 0, "edge": 1, "every": 2}
_LOG_LEVELS = {"error": 0, "warn": 1, "info": 2, "debug": 3}


class FabricError(Exception):
    """An error from libskillfab: its code (SF_ERR_*) and message."""

    def __init__(self, code, message):
        super().__init__(message)
        self.code = code


def _find_library():
    env = os.environ.get("SKILLFAB_LIB")
    if env:
        return env
    names = ["libskillfab.so"]
    dirs = []
    if os.environ.get("SKILLFAB_BIN_DIR"):
        dirs.append(os.environ["SKILLFAB_BIN_DIR"])
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    dirs += [os.path.join(root, "target", p) for p in ("release", "debug")]
    for d in dirs:
        for n in names:
            path = os.path.join(d, n)
            if os.path.exists(path):
                return path
    raise OSError(
        "libskillfab.so not found: build it (cargo build --workspace) or set SKILLFAB_LIB"
    )


lib = ctypes.CDLL(_find_library())

_c = ctypes
_P = _c.c_void_p
_S = _c.c_char_p
COMPUTE_FN = _c.CFUNCTYPE(_c.c_int32, _P, _P)
for _name, _res, _args in [
    ("sf_last_error", _S, []),
    ("sf_skill_new", _P, [_S, _c.c_int32]),
    ("sf_skill_free", None, [_P]),
    ("sf_skill_input", _c.c_int32, [_P, _S, _S]),
    ("sf_skill_output", _c.c_int32, [_P, _S, _S]),
    ("sf_skill_proposal", _c.c_int32, [_P, _S, _S]),
    ("sf_skill_param_float", _c.c_int32, [_P, _S, _c.c_double, _c.c_double, _c.c_double, _S]),
    ("sf_skill_param_int", _c.c_int32, [_P, _S, _c.c_int64, _c.c_int64, _c.c_int64, _S]),
    ("sf_skill_param_bool", _c.c_int32, [_P, _S, _c.c_bool, _S]),
    ("sf_skill_priority", _c.c_int32, [_P, _c.c_int32]),
    ("sf_skill_compute", _c.c_int32, [_P, COMPUTE_FN, _P]),
    ("sf_skill_run", _c.c_int32, [_P, _c.c_int32, _c.POINTER(_S)]),
    ("sf_input", _P, [_P, _c.c_int32, _c.c_size_t]),
    ("sf_input_cycle", _c.c_uint64, [_P, _c.c_int32]),
    ("sf_output", _P, [_P, _c.c_int32, _c.c_size_t]),
    ("sf_param_float", _c.c_double, [_P, _c.c_int32]),
    ("sf_param_int", _c.c_int64, [_P, _c.c_int32]),
    ("sf_param_bool", _c.c_bool, [_P, _c.c_int32]),
    ("sf_run_cycle", _c.c_uint64, [_P]),
    ("sf_run_time_ns", _c.c_uint64, [_P]),
    ("sf_run_period_ns", _c.c_uint64, [_P]),
    ("sf_run_lockstep", _c.c_bool, [_P]),
    ("sf_run_fail", _c.c_int32, [_P, _S]),
    ("sf_log", _c.c_int32, [_c.c_int32, _S]),
    ("sf_client_connect", _P, [_S]),
    ("sf_client_free", None, [_P]),
    ("sf_client_activate", _c.c_int32, [_P, _S]),
    ("sf_client_deactivate", _c.c_int32, [_P, _S]),
    ("sf_client_want", _c.c_int32, [_P, _S]),
    ("sf_client_release", _c.c_int32, [_P, _S]),
    ("sf_client_set_param", _c.c_int32, [_P, _S, _S, _S]),
    ("sf_client_get_param", _c.c_int32, [_P, _S, _S, _c.c_char_p, _c.c_size_t]),
    ("sf_client_query", _c.c_int32, [_P, _S, _c.c_char_p, _c.c_size_t]),
    ("sf_client_add_monitor", _c.c_int64, [_P, _S, _c.c_int32, _c.c_uint32]),
    ("sf_client_remove_monitor", _c.c_int32, [_P, _c.c_int64]),
    ("sf_client_next_event", _c.c_int32, [_P, _c.c_uint32, _c.c_char_p, _c.c_size_t]),
    ("sf_client_set_priority", _c.c_int32, [_P, _S, _c.c_int32]),
    ("sf_client_list", _c.c_int32, [_P, _c.c_char_p, _c.c_size_t]),
]:
    _f = getattr(lib, _name)
    _f.restype = _res
    _f.argtypes = _args


def _error(code=None):
    message = (lib.sf_last_error() or b"").decode("utf-8", "replace")
    return FabricError(code, message)


def _check(rc):
    if rc < 0:
        raise _error(rc)
    return rc


def _b(text):
    return text.encode("utf-8") if isinstance(text, str) else text


def log(message, level="info"):
    """A log line on stderr and the skill's log stream (the console, `skillfab ctl logs`)."""
    lib.sf_log(_LOG_LEVELS[level], _b(str(message)))


class Param:
    """A parameter: its default (its type: float, int or bool), inclusive bounds and doc."""

    def __init__(self, default, min=None, max=None, doc=""):
        self.default, self.min, self.max, self.doc = default, min, max, doc


class _Namespace:
    pass


class Run:
    """What `compute` gets besides inputs and outputs: the cycle, its time (`time_ns`: cycle ×
    period, or the cycle's start stamp when free-running; read it instead of a clock so a
    recorded run replays, docs/replay.md), the manager's `period_ns` (0: free-running),
    `lockstep`, a `random` generator seeded by the instance name and the cycle, and the
    parameters."""

    def __init__(self, cycle, params, time_ns=0, period_ns=0, lockstep=False, name=""):
        self.cycle = cycle
        self.params = params
        self.time_ns = time_ns
        self.period_ns = period_ns
        self.lockstep = lockstep
        self._seed = (name, cycle)

    @property
    def random(self):
        """A `random.Random` seeded by the instance name and the cycle: the same numbers in a
        replay and after a restart."""
        import random

        return random.Random(f"{self._seed[0]}:{self._seed[1]}")


class Skill:
    """Subclass it: `inputs`, `outputs`, `proposals` map port names to message classes from
    `skillfab.msgs`; `params` maps names to `Param`; `mode` is SYNC or ASYNC; `compute(self,
    run, i, o)` reads `i.<port>` and writes `o.<port>` (each output is sent only if written,
    and only if compute does not raise)."""

    inputs = {}
    outputs = {}
    proposals = {}
    params = {}
    mode = SYNC
    priority = 0
    kind = None

    def compute(self, run, i, o):
        raise NotImplementedError


class _Outputs:
    """Lazily loans an output's shared-memory sample on first attribute access."""

    def __init__(self, raw, ports):
        object.__setattr__(self, "_raw", raw)
        object.__setattr__(self, "_ports", ports)
        object.__setattr__(self, "_cells", {})

    def __getattr__(self, name):
        cells = object.__getattribute__(self, "_cells")
        if name in cells:
            return cells[name]
        ports = object.__getattribute__(self, "_ports")
        if name not in ports:
            raise AttributeError(f"no output '{name}'")
        idx, cls = ports[name]
        p = lib.sf_output(object.__getattribute__(self, "_raw"), idx, ctypes.sizeof(cls))
        if not p:
            raise _error()
        cells[name] = cls.from_address(p)
        return cells[name]

    def __setattr__(self, name, value):
        target = getattr(self, name)
        ctypes.memmove(ctypes.addressof(target), ctypes.addressof(value), ctypes.sizeof(target))


def _declare(cls, argv0):
    kind = cls.kind or os.path.splitext(os.path.basename(argv0))[0] or cls.__name__
    s = lib.sf_skill_new(_b(kind), cls.mode)
    if not s:
        raise _error()
    try:
        ins = {n: (_check(lib.sf_skill_input(s, _b(n), _b(t.TYPE_NAME))), t) for n, t in cls.inputs.items()}
        outs = {n: (_check(lib.sf_skill_output(s, _b(n), _b(t.TYPE_NAME))), t) for n, t in cls.outputs.items()}
        for n, t in cls.proposals.items():
            outs[n] = (_check(lib.sf_skill_proposal(s, _b(n), _b(t.TYPE_NAME))), t)
        params = {}
        for n, p in cls.params.items():
            doc = _b(p.doc)
            if isinstance(p.default, bool):
                idx = lib.sf_skill_param_bool(s, _b(n), p.default, doc)
                params[n] = (_check(idx), lib.sf_param_bool)
            elif isinstance(p.default, int):
                lo = -(2**63) if p.min is None else int(p.min)
                hi = 2**63 - 1 if p.max is None else int(p.max)
                idx = lib.sf_skill_param_int(s, _b(n), p.default, lo, hi, doc)
                params[n] = (_check(idx), lib.sf_param_int)
            else:
                lo = float("-inf") if p.min is None else float(p.min)
                hi = float("inf") if p.max is None else float(p.max)
                idx = lib.sf_skill_param_float(s, _b(n), float(p.default), lo, hi, doc)
                params[n] = (_check(idx), lib.sf_param_float)
        _check(lib.sf_skill_priority(s, cls.priority))
    except BaseException:
        lib.sf_skill_free(s)
        raise
    return s, ins, outs, params


def main(cls, argv=None):
    """Runs skill class `cls` as this process's skill until SIGINT/SIGTERM; exits with the
    SDK's exit code (0 after a clean shutdown)."""
    argv = list(sys.argv if argv is None else argv)
    try:
        s, ins, outs, params = _declare(cls, argv[0] if argv else "")
    except FabricError as e:
        print(f"{cls.__name__}: {e}", file=sys.stderr)
        sys.exit(1)
    skill = cls()
    # The instance name seeds `Run.random` (as the runtime names the instance).
    instance = argv[argv.index("--name") + 1] if "--name" in argv[:-1] else cls.__name__

    def body(raw, _user):
        try:
            i = _Namespace()
            for name, (idx, t) in ins.items():
                p = lib.sf_input(raw, idx, ctypes.sizeof(t))
                if not p:
                    raise _error()
                setattr(i, name, t.from_address(p))
            values = _Namespace()
            for name, (idx, getter) in params.items():
                setattr(values, name, getter(raw, idx))
            run = Run(
                lib.sf_run_cycle(raw),
                values,
                lib.sf_run_time_ns(raw),
                lib.sf_run_period_ns(raw),
                lib.sf_run_lockstep(raw),
                instance,
            )
            skill.compute(run, i, _Outputs(raw, outs))
            return 0
        except Exception as e:  # a failed run, not a dead skill
            lib.sf_run_fail(raw, _b(f"{type(e).__name__}: {e}"))
            return 1

    callback = COMPUTE_FN(body)  # kept alive until sf_skill_run returns
    _check(lib.sf_skill_compute(s, callback, None))
    args = (ctypes.c_char_p * len(argv))(*[_b(a) for a in argv])
    sys.exit(lib.sf_skill_run(s, len(argv), args))


class Client:
    """A sequencer's connection to a domain's manager."""

    def __init__(self, domain=None):
        self._c = lib.sf_client_connect(_b(domain) if domain else None)
        if not self._c:
            raise _error()

    def close(self):
        if self._c:
            lib.sf_client_free(self._c)
            self._c = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        self.close()

    def _text(self, f, *args, size=65536):
        buf = ctypes.create_string_buffer(size)
        _check(f(self._c, *args, buf, size))
        return buf.value.decode("utf-8")

    def activate(self, skill):
        _check(lib.sf_client_activate(self._c, _b(skill)))

    def deactivate(self, skill):
        _check(lib.sf_client_deactivate(self._c, _b(skill)))

    def want(self, skill):
        """Activates `skill` with every skill it reads from, transitively."""
        _check(lib.sf_client_want(self._c, _b(skill)))

    def release(self, skill):
        """Deactivates a wanted skill and what was activated only for it."""
        _check(lib.sf_client_release(self._c, _b(skill)))

    def set_param(self, skill, param, value):
        """Sets a parameter (checked against its type and bounds by the manager)."""
        if isinstance(value, bool):
            value = "true" if value else "false"
        _check(lib.sf_client_set_param(self._c, _b(skill), _b(param), _b(str(value))))

    def get_param(self, skill, param):
        return json.loads(self._text(lib.sf_client_get_param, _b(skill), _b(param)))

    def query(self, path):
        """The latest value at `skill.output[.field][index]`: (value, cycle)."""
        r = json.loads(self._text(lib.sf_client_query, _b(path)))
        return r["value"], r["cycle"]

    def monitor(self, expr, mode="once", hold=0):
        """Installs a monitor on a condition; returns its id. Firings arrive as events."""
        return _check(lib.sf_client_add_monitor(self._c, _b(expr), MONITOR_MODES[mode], hold))

    def remove_monitor(self, monitor_id):
        _check(lib.sf_client_remove_monitor(self._c, monitor_id))

    def set_priority(self, skill, priority):
        _check(lib.sf_client_set_priority(self._c, _b(skill), priority))

    def skills(self):
        """Every registered skill, as `skillfab ctl --json ls` prints them."""
        return json.loads(self._text(lib.sf_client_list))

    def next_event(self, timeout=1.0):
        """The next event as a dict, or None after `timeout` seconds."""
        size = 65536
        buf = ctypes.create_string_buffer(size)
        rc = _check(lib.sf_client_next_event(self._c, int(timeout * 1000), buf, size))
        return json.loads(buf.value.decode("utf-8")) if rc == 1 else None
