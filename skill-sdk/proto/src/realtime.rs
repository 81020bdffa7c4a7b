//! Real-time mode of a fabric's threads: a real-time scheduling class and priority, CPU
//! affinity and locked memory, asked for by a [`RealTime`] and applied by [`RealTime::apply`]
//! to the calling thread (the class and the affinity) and its process (the memory), as
//! ros2_control's controller manager and `realtime_tools` do.
//!
//! A machine may refuse any part (no privilege, a CPU that does not exist, a lock limit): the
//! refusal is an [`Applied`]'s [`NotGranted`], a sentence with the errno and the remedy, and
//! the thread runs on without that part — real-time mode never stops a fabric. Who applies
//! what (a skill's serving thread, the manager's cycle thread), and how a launch file asks
//! for it, is in `docs/realtime.md`.
//!
//! The compact form (`--realtime` of the benchmarks, the logs): `POLICY:PRIORITY[@CPUS][+mlock]`,
//! e.g. `fifo:80`, `rr:10@1`, `fifo:80@0-1,3+mlock`.

use nix::errno::Errno;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// A real-time scheduling policy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum Policy {
    /// `SCHED_FIFO`: runs until it blocks or a higher priority preempts it.
    #[default]
    #[serde(rename = "fifo")]
    Fifo,
    /// `SCHED_RR`: as FIFO, with a time slice among threads of equal priority.
    #[serde(rename = "rr")]
    RoundRobin,
}

impl Policy {
    /// The kernel's name: `SCHED_FIFO`, `SCHED_RR`.
    pub fn kernel_name(self) -> &'static str {
        match self {
            Policy::Fifo => "SCHED_FIFO",
            Policy::RoundRobin => "SCHED_RR",
        }
    }

    /// The compact form's name: `fifo`, `rr`.
    pub fn short_name(self) -> &'static str {
        match self {
            Policy::Fifo => "fifo",
            Policy::RoundRobin => "rr",
        }
    }

    fn libc(self) -> nix::libc::c_int {
        match self {
            Policy::Fifo => nix::libc::SCHED_FIFO,
            Policy::RoundRobin => nix::libc::SCHED_RR,
        }
    }
}

impl fmt::Display for Policy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.kernel_name())
    }
}

/// A real-time priority, 1 (lowest) to 99 (highest).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(try_from = "u8", into = "u8")]
pub struct Priority(u8);

impl Priority {
    /// The lowest real-time priority.
    pub const MIN: Priority = Priority(1);
    /// The highest real-time priority.
    pub const MAX: Priority = Priority(99);

    /// `p` if it is a real-time priority (1..=99).
    pub fn new(p: u8) -> Result<Priority, SpecError> {
        if (1..=99).contains(&p) {
            Ok(Priority(p))
        } else {
            Err(SpecError::Priority {
                given: p.to_string(),
            })
        }
    }

    /// Its value.
    pub fn get(self) -> u8 {
        self.0
    }

    /// One above, at most 99.
    pub fn above(self) -> Priority {
        Priority(self.0.saturating_add(1).min(99))
    }
}

impl TryFrom<u8> for Priority {
    type Error = SpecError;
    fn try_from(p: u8) -> Result<Priority, SpecError> {
        Priority::new(p)
    }
}

impl From<Priority> for u8 {
    fn from(p: Priority) -> u8 {
        p.0
    }
}

impl fmt::Display for Priority {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

/// A non-empty set of CPU numbers, sorted. Text: `1`, `0,1`, `0-3,6` (as the kernel's lists
/// in `/sys/devices/system/cpu`); in a launch file an array, `[0, 1]`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "Vec<usize>", into = "Vec<usize>")]
pub struct CpuList(Vec<usize>);

impl CpuList {
    /// The CPUs of `cpus` (sorted, each once); an empty list, or a CPU past what a CPU set
    /// holds, is refused.
    pub fn new(mut cpus: Vec<usize>) -> Result<CpuList, SpecError> {
        if cpus.is_empty() {
            return Err(SpecError::NoCpus);
        }
        if let Some(&cpu) = cpus.iter().find(|&&c| c >= CPU_SETSIZE) {
            return Err(SpecError::CpuBeyondSet {
                cpu,
                max: CPU_SETSIZE - 1,
            });
        }
        cpus.sort_unstable();
        cpus.dedup();
        Ok(CpuList(cpus))
    }

    /// The CPUs, ascending.
    pub fn cpus(&self) -> &[usize] {
        &self.0
    }

    /// Whether `cpu` is in the list.
    pub fn contains(&self, cpu: usize) -> bool {
        self.0.binary_search(&cpu).is_ok()
    }

    /// The CPUs of a kernel list (`/sys/devices/system/cpu/online`: `0-3,6`); `None` for an
    /// empty or unreadable one.
    fn read(path: &str) -> Option<CpuList> {
        std::fs::read_to_string(path).ok()?.trim().parse().ok()
    }
}

impl TryFrom<Vec<usize>> for CpuList {
    type Error = SpecError;
    fn try_from(cpus: Vec<usize>) -> Result<CpuList, SpecError> {
        CpuList::new(cpus)
    }
}

impl From<CpuList> for Vec<usize> {
    fn from(c: CpuList) -> Vec<usize> {
        c.0
    }
}

impl FromStr for CpuList {
    type Err = SpecError;
    fn from_str(s: &str) -> Result<CpuList, SpecError> {
        let bad = || SpecError::Cpus {
            given: s.to_string(),
        };
        let mut cpus = Vec::new();
        for part in s.split(',').map(str::trim) {
            let (lo, hi) = match part.split_once('-') {
                Some((lo, hi)) => (lo.trim(), hi.trim()),
                None => (part, part),
            };
            let lo: usize = lo.parse().map_err(|_| bad())?;
            let hi: usize = hi.parse().map_err(|_| bad())?;
            // More CPUs than a cpu_set_t holds is a typing mistake, not a machine.
            if lo > hi {
                return Err(bad());
            }
            if hi >= CPU_SETSIZE {
                return Err(SpecError::CpuBeyondSet {
                    cpu: hi,
                    max: CPU_SETSIZE - 1,
                });
            }
            cpus.extend(lo..=hi);
        }
        CpuList::new(cpus)
    }
}

impl fmt::Display for CpuList {
    /// Runs of consecutive CPUs as ranges: `0-3,6`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut i = 0;
        let mut first = true;
        while i < self.0.len() {
            let start = self.0[i];
            let mut end = start;
            while i + 1 < self.0.len() && self.0[i + 1] == end + 1 {
                i += 1;
                end = self.0[i];
            }
            if !first {
                f.write_str(",")?;
            }
            first = false;
            if start == end {
                write!(f, "{start}")?;
            } else {
                write!(f, "{start}-{end}")?;
            }
            i += 1;
        }
        Ok(())
    }
}

/// CPUs a `cpu_set_t` holds.
const CPU_SETSIZE: usize = 1024;

/// What real-time mode asks for one thread (and its process's memory).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RealTime {
    /// The scheduling policy (default FIFO).
    #[serde(default)]
    pub policy: Policy,
    /// The real-time priority.
    pub priority: Priority,
    /// Pin the thread to these CPUs (default: not pinned).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpus: Option<CpuList>,
    /// Lock the process's memory (`mlockall`), pre-fault some stack, and keep freed heap
    /// memory (default true: a page fault on the cycle's path costs what a cycle does).
    #[serde(default = "yes")]
    pub lock_memory: bool,
}

fn yes() -> bool {
    true
}

/// A malformed real-time request.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SpecError {
    /// A priority outside 1..=99.
    #[error("real-time priority '{given}' is not one of 1..=99")]
    Priority {
        /// As given.
        given: String,
    },
    /// A policy other than fifo or rr.
    #[error("real-time policy '{given}' is not fifo or rr")]
    Policy {
        /// As given.
        given: String,
    },
    /// Text that is not a CPU list.
    #[error("'{given}' is not a CPU list (e.g. 1, 0,1 or 0-3)")]
    Cpus {
        /// As given.
        given: String,
    },
    /// An empty CPU list.
    #[error("the CPU list is empty (leave it out not to pin)")]
    NoCpus,
    /// A CPU number past what a CPU set holds.
    #[error("CPU {cpu} is past the last a CPU set holds ({max})")]
    CpuBeyondSet {
        /// As given.
        cpu: usize,
        /// The last CPU a set holds.
        max: usize,
    },
    /// Compact-form text of another shape.
    #[error("'{given}' is not a real-time spec: POLICY:PRIORITY[@CPUS][+mlock], e.g. fifo:80@1")]
    Form {
        /// As given.
        given: String,
    },
}

/// `fifo:80`, `rr:10`: a policy and a priority (the `--realtime` flag of skills and the
/// manager).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sched {
    /// The policy.
    pub policy: Policy,
    /// Its priority.
    pub priority: Priority,
}

impl FromStr for Sched {
    type Err = SpecError;
    fn from_str(s: &str) -> Result<Sched, SpecError> {
        let (policy, priority) = s.split_once(':').ok_or_else(|| SpecError::Form {
            given: s.to_string(),
        })?;
        let policy = match policy.trim() {
            "fifo" => Policy::Fifo,
            "rr" => Policy::RoundRobin,
            other => {
                return Err(SpecError::Policy {
                    given: other.to_string(),
                });
            }
        };
        let priority = priority
            .trim()
            .parse::<u8>()
            .map_err(|_| SpecError::Priority {
                given: priority.trim().to_string(),
            })
            .and_then(Priority::new)?;
        Ok(Sched { policy, priority })
    }
}

impl fmt::Display for Sched {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.policy.short_name(), self.priority)
    }
}

impl RealTime {
    /// `policy:priority`, no pinning, memory not locked.
    pub fn new(sched: Sched) -> RealTime {
        RealTime {
            policy: sched.policy,
            priority: sched.priority,
            cpus: None,
            lock_memory: false,
        }
    }

    /// Its policy and priority.
    pub fn sched(&self) -> Sched {
        Sched {
            policy: self.policy,
            priority: self.priority,
        }
    }

    /// The command-line flags that ask a skill (or the manager) for this:
    /// `--realtime fifo:80 [--cpus 0-1] [--lock-memory]`.
    pub fn flags(&self) -> Vec<String> {
        let mut a = vec!["--realtime".to_string(), self.sched().to_string()];
        if let Some(c) = &self.cpus {
            a.extend(["--cpus".to_string(), c.to_string()]);
        }
        if self.lock_memory {
            a.push("--lock-memory".into());
        }
        a
    }

    /// Applies this to the calling thread — its scheduling policy and priority (with
    /// `SCHED_RESET_ON_FORK`: threads it starts later, a logger's, run as ordinary ones) and
    /// its CPU affinity — and to its process's memory (locked, current and future, some stack
    /// pre-faulted; glibc told to keep freed memory). Whatever the machine refuses is in the
    /// result with its reason; nothing fails.
    pub fn apply(&self) -> Applied {
        let mut applied = Applied::default();
        match set_scheduler(self.policy, self.priority) {
            Ok(()) => applied.granted.push(Grant::Scheduling(self.sched())),
            Err(errno) => applied.refused.push(NotGranted::Scheduling {
                sched: self.sched(),
                errno,
                rtprio_limit: rlimit(nix::libc::RLIMIT_RTPRIO),
                cap_sys_nice: has_capability(CAP_SYS_NICE),
            }),
        }
        if let Some(cpus) = &self.cpus {
            match pin(cpus) {
                Ok(()) => {
                    applied.granted.push(Grant::Affinity(cpus.clone()));
                    // Pinned, but only an isolated CPU is the thread's alone.
                    let isolated = CpuList::read("/sys/devices/system/cpu/isolated");
                    let shared: Vec<usize> = cpus
                        .cpus()
                        .iter()
                        .copied()
                        .filter(|&c| !isolated.as_ref().is_some_and(|i| i.contains(c)))
                        .collect();
                    if let Ok(shared) = CpuList::new(shared) {
                        applied
                            .refused
                            .push(NotGranted::NotIsolated { cpus: shared });
                    }
                }
                Err(refusal) => applied.refused.push(refusal),
            }
        }
        if self.lock_memory {
            let limit_kib = rlimit(nix::libc::RLIMIT_MEMLOCK).map(|b| b / 1024);
            match limit_kib {
                // Future mappings count against a finite limit: once locked memory reaches it,
                // an allocation fails. Not attempted.
                Some(limit_kib) if !has_capability(CAP_IPC_LOCK) => {
                    applied.refused.push(NotGranted::MemoryLimit { limit_kib });
                }
                _ => match lock_memory() {
                    Ok(()) => applied.granted.push(Grant::MemoryLocked),
                    Err(errno) => applied
                        .refused
                        .push(NotGranted::MemoryLock { errno, limit_kib }),
                },
            }
        }
        applied
    }
}

impl fmt::Display for RealTime {
    /// The compact form: `fifo:80@0-1+mlock`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.sched())?;
        if let Some(c) = &self.cpus {
            write!(f, "@{c}")?;
        }
        if self.lock_memory {
            f.write_str("+mlock")?;
        }
        Ok(())
    }
}

impl FromStr for RealTime {
    type Err = SpecError;
    /// The compact form: `POLICY:PRIORITY[@CPUS][+mlock]`.
    fn from_str(s: &str) -> Result<RealTime, SpecError> {
        let (rest, lock_memory) = match s.trim().split_once('+') {
            Some((rest, "mlock")) => (rest, true),
            Some(_) => {
                return Err(SpecError::Form {
                    given: s.to_string(),
                });
            }
            None => (s.trim(), false),
        };
        let (sched, cpus) = match rest.split_once('@') {
            Some((sched, cpus)) => (sched, Some(cpus.parse::<CpuList>()?)),
            None => (rest, None),
        };
        let sched: Sched = sched.parse()?;
        Ok(RealTime {
            cpus,
            lock_memory,
            ..RealTime::new(sched)
        })
    }
}

/// A part of a [`RealTime`] the machine granted.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum Grant {
    /// The thread runs under this policy and priority.
    Scheduling(Sched),
    /// The thread runs only on these CPUs.
    Affinity(CpuList),
    /// The process's memory is locked and some stack pre-faulted.
    MemoryLocked,
}

impl fmt::Display for Grant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Grant::Scheduling(s) => write!(f, "{} priority {}", s.policy, s.priority),
            Grant::Affinity(c) => write!(f, "pinned to CPU {c}"),
            Grant::MemoryLocked => f.write_str("memory locked"),
        }
    }
}

/// A part of a [`RealTime`] the machine refused (or granted short of what real-time needs):
/// a sentence with the reason, the remedy, and how the thread runs on.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum NotGranted {
    /// The scheduling class was refused.
    #[error("{} priority {} refused ({errno:?}): {}; running on under SCHED_OTHER",
        .sched.policy, .sched.priority, sched_remedy(.errno, .sched, .rtprio_limit, .cap_sys_nice))]
    Scheduling {
        /// What was asked.
        sched: Sched,
        /// The kernel's answer.
        errno: Errno,
        /// `RLIMIT_RTPRIO` (soft), if readable (`None` also for unlimited).
        rtprio_limit: Option<u64>,
        /// Whether the process has `CAP_SYS_NICE` (the limit does not bind it then).
        cap_sys_nice: bool,
    },
    /// CPUs of the list are not online here.
    #[error("CPU {missing} does not exist ({} online: {online}); not pinned, running on any CPU", .online.cpus().len())]
    CpuMissing {
        /// The CPUs asked for that are not online.
        missing: CpuList,
        /// The CPUs online.
        online: CpuList,
    },
    /// CPUs of the list exist but this process may not run there.
    #[error(
        "CPU {outside} is outside this process's CPUs ({allowed}: a cpuset or taskset restricts it); not pinned, running on any CPU it may use"
    )]
    CpuNotAllowed {
        /// The CPUs asked for that the process may not use.
        outside: CpuList,
        /// The CPUs it may use.
        allowed: CpuList,
    },
    /// `sched_setaffinity` failed for another reason.
    #[error("pinning to CPU {cpus} refused ({errno:?}); running on any CPU")]
    Affinity {
        /// What was asked.
        cpus: CpuList,
        /// The kernel's answer.
        errno: Errno,
    },
    /// Pinned, but to CPUs other processes share.
    #[error(
        "CPU {cpus} is not isolated (isolcpus= on the kernel command line, or a cpuset): other processes share it; pinned anyway"
    )]
    NotIsolated {
        /// The pinned CPUs that are not isolated.
        cpus: CpuList,
    },
    /// Locking memory was not attempted: the process's lock limit is finite and does not
    /// bind it (no `CAP_IPC_LOCK`), and locked future memory that outgrows a limit makes
    /// allocations fail.
    #[error(
        "locking memory not attempted: `ulimit -l` is {limit_kib} KiB without CAP_IPC_LOCK, and once locked memory reaches the limit allocations fail; needs CAP_IPC_LOCK or `ulimit -l unlimited` (memlock in /etc/security/limits.d, LimitMEMLOCK=infinity for a systemd service); running on with memory that may be paged out"
    )]
    MemoryLimit {
        /// `RLIMIT_MEMLOCK` (soft) in KiB.
        limit_kib: u64,
    },
    /// `mlockall` was refused.
    #[error("locking memory refused ({errno:?}): needs CAP_IPC_LOCK or `ulimit -l unlimited` ({}; memlock in /etc/security/limits.d, LimitMEMLOCK=infinity for a systemd service); running on with memory that may be paged out",
        .limit_kib.map_or("now unlimited".to_string(), |k| format!("now {k} KiB")))]
    MemoryLock {
        /// The kernel's answer.
        errno: Errno,
        /// `RLIMIT_MEMLOCK` (soft) in KiB, if limited.
        limit_kib: Option<u64>,
    },
}

/// What to do about a refused scheduling class.
fn sched_remedy(
    errno: &Errno,
    sched: &Sched,
    rtprio_limit: &Option<u64>,
    cap_sys_nice: &bool,
) -> String {
    let priority = sched.priority;
    match *errno {
        // Allowed by capability and still refused: real-time group scheduling left the
        // process's cgroup no real-time runtime (a container's default).
        Errno::EPERM if *cap_sys_nice => "the process has CAP_SYS_NICE but its cgroup has no \
             real-time runtime (cpu.rt_runtime_us; in a container: --cpu-rt-runtime)"
            .to_string(),
        Errno::EPERM => format!(
            "needs CAP_SYS_NICE or `ulimit -r` ≥ {priority} ({}; rtprio in \
             /etc/security/limits.d, LimitRTPRIO= for a systemd service)",
            rtprio_limit.map_or("now unlimited".to_string(), |l| format!("now {l}"))
        ),
        _ => "the kernel does not accept this policy and priority".to_string(),
    }
}

/// What [`RealTime::apply`] got: the parts granted and the parts refused.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Applied {
    /// Granted, in the order applied.
    pub granted: Vec<Grant>,
    /// Refused (or short of real-time), each with its reason and remedy.
    pub refused: Vec<NotGranted>,
}

impl Applied {
    /// Says in the log what was granted (info) and each refusal (a warning): `who` names the
    /// thread (`the manager's cycle thread`, `the skill's thread`).
    pub fn log(&self, who: &str) {
        if !self.granted.is_empty() {
            tracing::info!("real-time mode of {who}: {self}");
        }
        for r in &self.refused {
            tracing::warn!("real-time mode of {who}: {r}");
        }
    }
}

impl fmt::Display for Applied {
    /// The granted parts, `SCHED_FIFO priority 80, pinned to CPU 1, memory locked`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.granted.is_empty() {
            return f.write_str("nothing granted");
        }
        for (i, g) in self.granted.iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            write!(f, "{g}")?;
        }
        Ok(())
    }
}

/// The scheduling policy and priority of the calling thread.
fn set_scheduler(policy: Policy, priority: Priority) -> Result<(), Errno> {
    let param = nix::libc::sched_param {
        sched_priority: nix::libc::c_int::from(priority.get()),
    };
    // SAFETY: pid 0 is the calling thread; `param` is a valid sched_param the call only reads.
    let r = unsafe {
        nix::libc::sched_setscheduler(0, policy.libc() | nix::libc::SCHED_RESET_ON_FORK, &param)
    };
    Errno::result(r).map(drop)
}

/// The calling thread's policy and priority, if it runs under a real-time one.
pub fn current_sched() -> Option<Sched> {
    // SAFETY: pid 0 is the calling thread; no memory is passed.
    let policy = unsafe { nix::libc::sched_getscheduler(0) } & !nix::libc::SCHED_RESET_ON_FORK;
    let policy = match policy {
        nix::libc::SCHED_FIFO => Policy::Fifo,
        nix::libc::SCHED_RR => Policy::RoundRobin,
        _ => return None,
    };
    let mut param = nix::libc::sched_param { sched_priority: 0 };
    // SAFETY: pid 0 is the calling thread; `param` is a valid sched_param the call writes.
    if unsafe { nix::libc::sched_getparam(0, &mut param) } != 0 {
        return None;
    }
    let priority = u8::try_from(param.sched_priority)
        .ok()
        .and_then(|p| Priority::new(p).ok())?;
    Some(Sched { policy, priority })
}

/// The CPUs the calling thread may run on.
pub fn current_affinity() -> Option<CpuList> {
    // SAFETY: an all-zero cpu_set_t is an empty set.
    let mut set: nix::libc::cpu_set_t = unsafe { std::mem::zeroed() };
    // SAFETY: pid 0 is the calling thread; `set` is a cpu_set_t of the size passed.
    let r = unsafe {
        nix::libc::sched_getaffinity(0, std::mem::size_of::<nix::libc::cpu_set_t>(), &mut set)
    };
    if r != 0 {
        return None;
    }
    // SAFETY: CPU_ISSET reads a bit of the set, below CPU_SETSIZE.
    let cpus = (0..CPU_SETSIZE)
        .filter(|&c| unsafe { nix::libc::CPU_ISSET(c, &set) })
        .collect();
    CpuList::new(cpus).ok()
}

/// Pins the calling thread to `cpus`, after checking they exist and are the process's to use
/// (the kernel answers both with a bare EINVAL).
fn pin(cpus: &CpuList) -> Result<(), NotGranted> {
    if let Some(online) = CpuList::read("/sys/devices/system/cpu/online") {
        let missing: Vec<usize> = cpus
            .cpus()
            .iter()
            .copied()
            .filter(|&c| !online.contains(c))
            .collect();
        if let Ok(missing) = CpuList::new(missing) {
            return Err(NotGranted::CpuMissing { missing, online });
        }
    }
    if let Some(allowed) = current_affinity() {
        let outside: Vec<usize> = cpus
            .cpus()
            .iter()
            .copied()
            .filter(|&c| !allowed.contains(c))
            .collect();
        if let Ok(outside) = CpuList::new(outside) {
            return Err(NotGranted::CpuNotAllowed { outside, allowed });
        }
    }
    // SAFETY: an all-zero cpu_set_t is an empty set.
    let mut set: nix::libc::cpu_set_t = unsafe { std::mem::zeroed() };
    for &c in cpus.cpus() {
        // SAFETY: a CpuList's CPUs are below CPU_SETSIZE (CpuList::new), in the set's bounds.
        unsafe { nix::libc::CPU_SET(c, &mut set) };
    }
    // SAFETY: pid 0 is the calling thread; `set` is a cpu_set_t of the size passed.
    let r = unsafe {
        nix::libc::sched_setaffinity(0, std::mem::size_of::<nix::libc::cpu_set_t>(), &set)
    };
    Errno::result(r)
        .map(drop)
        .map_err(|errno| NotGranted::Affinity {
            cpus: cpus.clone(),
            errno,
        })
}

/// Stack the locking pre-faults: the deepest a cycle's path is expected to go without a page
/// fault (the main thread's stack is 8 MiB by default, a Rust thread's 2 MiB).
const PREFAULT_STACK: usize = 256 * 1024;

/// Locks the process's memory, current and future; touches [`PREFAULT_STACK`] of stack so
/// those pages are mapped (and locked) now, not on the cycle's path; and has glibc keep the
/// memory a free returns (no trimming, no mmap for large blocks), so a later allocation does
/// not fault in fresh pages.
fn lock_memory() -> Result<(), Errno> {
    // SAFETY: mlockall takes flags only.
    let r = unsafe { nix::libc::mlockall(nix::libc::MCL_CURRENT | nix::libc::MCL_FUTURE) };
    Errno::result(r)?;
    prefault_stack();
    #[cfg(target_env = "gnu")]
    // SAFETY: mallopt takes two integers; these are glibc's documented parameters.
    unsafe {
        nix::libc::mallopt(nix::libc::M_TRIM_THRESHOLD, -1);
        nix::libc::mallopt(nix::libc::M_MMAP_MAX, 0);
    }
    Ok(())
}

/// Writes to [`PREFAULT_STACK`] bytes of this thread's stack.
#[inline(never)]
fn prefault_stack() {
    let mut stack = [0u8; PREFAULT_STACK];
    // One write per page is enough; black_box keeps the compiler from dropping them.
    for i in (0..PREFAULT_STACK).step_by(4096) {
        stack[i] = 1;
    }
    std::hint::black_box(&mut stack);
}

/// A resource limit's soft value; `None` if unreadable or unlimited.
fn rlimit(resource: nix::libc::__rlimit_resource_t) -> Option<u64> {
    let mut l = nix::libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: `l` is a valid rlimit the call writes.
    if unsafe { nix::libc::getrlimit(resource, &mut l) } != 0
        || l.rlim_cur == nix::libc::RLIM_INFINITY
    {
        return None;
    }
    Some(l.rlim_cur)
}

/// `CAP_IPC_LOCK`'s bit in the capability sets.
const CAP_IPC_LOCK: u32 = 14;
/// `CAP_SYS_NICE`'s bit in the capability sets.
const CAP_SYS_NICE: u32 = 23;

/// Whether the process's effective capabilities (`/proc/self/status`) include `cap`.
fn has_capability(cap: u32) -> bool {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("CapEff:"))
                .and_then(|hex| u64::from_str_radix(hex.trim(), 16).ok())
        })
        .is_some_and(|bits| bits & (1 << cap) != 0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cpus(s: &str) -> CpuList {
        s.parse().unwrap()
    }

    #[test]
    fn cpu_lists_read_as_the_kernel_writes_them() {
        assert_eq!(cpus("1").cpus(), [1]);
        assert_eq!(cpus("0,1").cpus(), [0, 1]);
        assert_eq!(cpus("0-3,6").cpus(), [0, 1, 2, 3, 6]);
        assert_eq!(cpus("3, 1-2, 1").cpus(), [1, 2, 3], "sorted, each once");
        assert_eq!(cpus("0-3,6,8-9").to_string(), "0-3,6,8-9");
        assert_eq!(cpus("2,0,1").to_string(), "0-2");
        for bad in ["", "a", "1-", "3-1", "1,,2", "-1", "5000"] {
            assert!(bad.parse::<CpuList>().is_err(), "'{bad}' was taken");
        }
        assert_eq!(CpuList::new(Vec::new()), Err(SpecError::NoCpus));
        assert_eq!(
            CpuList::new(vec![1, 4096]).unwrap_err().to_string(),
            "CPU 4096 is past the last a CPU set holds (1023)"
        );
    }

    #[test]
    fn the_compact_form_reads_back_what_it_writes() {
        let rt: RealTime = "fifo:80".parse().unwrap();
        assert_eq!(
            rt,
            RealTime::new(Sched {
                policy: Policy::Fifo,
                priority: Priority(80)
            })
        );
        let rt: RealTime = "rr:10@0-1+mlock".parse().unwrap();
        assert_eq!(rt.policy, Policy::RoundRobin);
        assert_eq!(rt.priority.get(), 10);
        assert_eq!(rt.cpus, Some(cpus("0,1")));
        assert!(rt.lock_memory);
        for text in ["fifo:1", "rr:99@3", "fifo:50@0-2,5+mlock", "fifo:7+mlock"] {
            assert_eq!(text.parse::<RealTime>().unwrap().to_string(), text);
        }
        assert_eq!(
            rt.flags(),
            ["--realtime", "rr:10", "--cpus", "0-1", "--lock-memory"]
        );
    }

    #[test]
    fn malformed_specs_say_what_is_wrong() {
        let err = |s: &str| s.parse::<RealTime>().unwrap_err().to_string();
        assert_eq!(err("fifo:0"), "real-time priority '0' is not one of 1..=99");
        assert_eq!(
            err("fifo:100"),
            "real-time priority '100' is not one of 1..=99"
        );
        assert_eq!(
            err("fifo:-3"),
            "real-time priority '-3' is not one of 1..=99"
        );
        assert_eq!(
            err("deadline:5"),
            "real-time policy 'deadline' is not fifo or rr"
        );
        assert!(err("80").contains("POLICY:PRIORITY"), "{}", err("80"));
        assert!(err("fifo:80+lock").contains("POLICY:PRIORITY"));
        assert!(err("fifo:80@").contains("not a CPU list"));
    }

    #[test]
    fn a_launch_file_table_reads_with_its_defaults_and_refuses_bad_values() {
        let rt: RealTime = toml_like(r#"{"priority": 20}"#).unwrap();
        assert_eq!(rt.policy, Policy::Fifo);
        assert!(rt.lock_memory, "locked by default");
        assert_eq!(rt.cpus, None);
        let rt: RealTime =
            toml_like(r#"{"policy": "rr", "priority": 5, "cpus": [1, 0], "lock_memory": false}"#)
                .unwrap();
        assert_eq!(rt.to_string(), "rr:5@0-1");
        for bad in [
            r#"{"priority": 0}"#,
            r#"{"priority": 100}"#,
            r#"{"priority": 5, "cpus": []}"#,
            r#"{"priority": 5, "policy": "other"}"#,
            r#"{"priority": 5, "nice": 3}"#,
        ] {
            assert!(toml_like(bad).is_err(), "{bad} was taken");
        }
    }

    fn toml_like(json: &str) -> Result<RealTime, serde_json::Error> {
        serde_json::from_str(json)
    }

    #[test]
    fn refusals_are_sentences_with_the_errno_and_the_remedy() {
        let sched = Sched {
            policy: Policy::Fifo,
            priority: Priority(80),
        };
        let no_privilege = NotGranted::Scheduling {
            sched,
            errno: Errno::EPERM,
            rtprio_limit: Some(0),
            cap_sys_nice: false,
        };
        assert_eq!(
            no_privilege.to_string(),
            "SCHED_FIFO priority 80 refused (EPERM): needs CAP_SYS_NICE or `ulimit -r` ≥ 80 \
             (now 0; rtprio in /etc/security/limits.d, LimitRTPRIO= for a systemd service); \
             running on under SCHED_OTHER"
        );
        let cgroup = NotGranted::Scheduling {
            sched,
            errno: Errno::EPERM,
            rtprio_limit: Some(0),
            cap_sys_nice: true,
        };
        assert!(cgroup.to_string().contains("cpu.rt_runtime_us"), "{cgroup}");
        let missing = NotGranted::CpuMissing {
            missing: cpus("5"),
            online: cpus("0-1"),
        };
        assert_eq!(
            missing.to_string(),
            "CPU 5 does not exist (2 online: 0-1); not pinned, running on any CPU"
        );
        let shared = NotGranted::NotIsolated { cpus: cpus("1") };
        assert!(
            shared
                .to_string()
                .starts_with("CPU 1 is not isolated (isolcpus="),
            "{shared}"
        );
        let lock = NotGranted::MemoryLock {
            errno: Errno::ENOMEM,
            limit_kib: Some(8192),
        };
        assert_eq!(
            lock.to_string(),
            "locking memory refused (ENOMEM): needs CAP_IPC_LOCK or `ulimit -l unlimited` \
             (now 8192 KiB; memlock in /etc/security/limits.d, LimitMEMLOCK=infinity for a \
             systemd service); running on with memory that may be paged out"
        );
        let limit = NotGranted::MemoryLimit { limit_kib: 8192 };
        assert!(
            limit.to_string().starts_with(
                "locking memory not attempted: `ulimit -l` is 8192 KiB without CAP_IPC_LOCK"
            ),
            "{limit}"
        );
    }

    #[test]
    fn a_cpu_that_does_not_exist_is_refused_and_the_thread_is_not_pinned() {
        // On a thread of its own: the test's threads keep their affinity.
        let (refused, after, before) = std::thread::spawn(|| {
            let before = current_affinity();
            let r = pin(&CpuList::new(vec![CPU_SETSIZE - 1]).unwrap());
            (r, current_affinity(), before)
        })
        .join()
        .unwrap();
        match refused {
            Err(NotGranted::CpuMissing { missing, .. }) => {
                assert_eq!(missing.cpus(), [CPU_SETSIZE - 1]);
            }
            other => panic!("not refused as missing: {other:?}"),
        }
        assert_eq!(after, before, "the affinity is left as it was");
    }

    #[test]
    fn pinning_to_an_allowed_cpu_is_granted_on_that_thread_only() {
        let Some(allowed) = current_affinity() else {
            panic!("the test thread's affinity cannot be read");
        };
        let one = CpuList::new(vec![allowed.cpus()[0]]).unwrap();
        let want = one.clone();
        let pinned = std::thread::spawn(move || pin(&want).map(|()| current_affinity()))
            .join()
            .unwrap();
        assert_eq!(pinned, Ok(Some(one)));
        assert_eq!(
            current_affinity(),
            Some(allowed),
            "other threads are not pinned"
        );
    }
}
