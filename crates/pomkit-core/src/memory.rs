//! The memory budget every job is checked against before it starts, and the largest image side
//! pomkit handles (docs/LIMITS.md).
//!
//! A job (a render, a displaced mesh, a decoded image, a generated map) first sums the big
//! buffers it will allocate and compares the sum with [`available_bytes`], the smallest of:
//!
//! - the machine's free memory: on Linux the kernel's `MemAvailable` (from `/proc/meminfo`), or
//!   instead the value of the environment variable [`LIMIT_VAR`] (`POMKIT_MEMORY_LIMIT=4GiB`)
//!   when it is set;
//! - the headroom under the process's cgroup memory limit (v2 `memory.max` less
//!   `memory.current`, v1 `memory.limit_in_bytes` less `memory.usage_in_bytes`, of its cgroup
//!   and every parent), as in a container;
//! - the headroom under its address-space limit (`RLIMIT_AS`, `ulimit -v`: "Max address space"
//!   in `/proc/self/limits` less `VmSize` in `/proc/self/status`), less a margin for the
//!   virtual reservations that are not the job's buffers (thread stacks, malloc arenas).
//!
//! The hard limits are read again at every check, so that what the process already holds is
//! counted. A job that will not fit is refused up front with a [`MemoryError`] that gives both
//! figures, which limit is the smallest, and what to change, rather than aborting half-way
//! through with the allocator's "memory allocation of N bytes failed". Where none of these
//! exists nothing is refused on this basis.
//!
//! Buffers whose size comes from input are also allocated fallibly ([`try_vec`]), so that even an
//! estimate that is too low gives an error, not an abort.

use std::collections::TryReserveError;
use std::fmt;

/// The largest width or height, in pixels or texels, of anything pomkit renders, generates or
/// reads: `--size`, `generate`, built-in height and colour maps in scene files, image files.
pub const MAX_SIZE: u32 = 16384;

/// The environment variable that sets the memory budget instead of `MemAvailable`: a number of
/// bytes, optionally with a unit (`B`, `KiB`, `MiB`, `GiB`, `TiB`, or `K`, `M`, `G`, `T` for the
/// same binary units; `KB`, `MB`, `GB`, `TB` are decimal), e.g. `POMKIT_MEMORY_LIMIT=4GiB`.
pub const LIMIT_VAR: &str = "POMKIT_MEMORY_LIMIT";

/// How much memory a job may use, and where that figure came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Budget {
    /// Bytes available.
    pub bytes: u64,
    /// Where the figure came from.
    pub source: BudgetSource,
}

/// Where a [`Budget`] came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BudgetSource {
    /// The environment variable [`LIMIT_VAR`].
    Variable,
    /// `MemAvailable` in `/proc/meminfo`.
    MemAvailable,
    /// The process's cgroup memory limit less the cgroup's usage.
    Cgroup,
    /// The process's address-space limit (`RLIMIT_AS`, `ulimit -v`) less its current size.
    AddressSpace,
}

impl BudgetSource {
    /// Whether the figure is a fixed amount for the whole job (the variable), rather than what
    /// is left now, with the process's current use already taken off.
    #[must_use]
    pub fn is_fixed(self) -> bool {
        self == BudgetSource::Variable
    }
}

impl fmt::Display for BudgetSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BudgetSource::Variable => write!(f, "{LIMIT_VAR}"),
            BudgetSource::MemAvailable => f.write_str("MemAvailable"),
            BudgetSource::Cgroup => f.write_str("the cgroup's memory limit"),
            BudgetSource::AddressSpace => f.write_str("the address-space limit, ulimit -v"),
        }
    }
}

/// Why a job cannot run in the memory there is.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum MemoryError {
    /// The job's estimate exceeds the budget.
    #[error("{what} needs about {}; {} is available ({from}): {advice}", format_bytes(*needed), format_bytes(*available))]
    TooBig {
        /// The job, e.g. "render of 16384x16384 with 5 AOVs".
        what: String,
        /// Bytes the job needs (an upper-bound estimate).
        needed: u64,
        /// Bytes available.
        available: u64,
        /// Where `available` came from.
        from: BudgetSource,
        /// What to change, e.g. "use a smaller --size or fewer AOVs".
        advice: String,
    },
    /// An allocation whose size came from input failed although the estimate said it would fit.
    #[error("{what}: cannot allocate {} ({reason}): {advice}", format_bytes(*bytes))]
    Allocation {
        /// The buffer.
        what: String,
        /// Its size.
        bytes: u64,
        /// The allocator's reason.
        reason: String,
        /// What to change.
        advice: String,
    },
    /// [`LIMIT_VAR`] is set to something that is not a size.
    #[error("{LIMIT_VAR}={value:?} is not a memory size: use bytes or a size with a unit, e.g. 4GiB or 512MiB")]
    BadLimit {
        /// The variable's value.
        value: String,
    },
}

/// Every budget that applies now: [`LIMIT_VAR`] when set, else `MemAvailable` on Linux; and
/// the headroom under the cgroup memory limit and the address-space limit when the process
/// has them.
///
/// # Errors
/// [`MemoryError::BadLimit`] when the variable is set but is not a size.
pub fn budgets() -> Result<Vec<Budget>, MemoryError> {
    let mut out = Vec::new();
    if let Some(value) = std::env::var_os(LIMIT_VAR) {
        let text = value.to_string_lossy();
        let bytes = parse_size(&text).ok_or_else(|| MemoryError::BadLimit { value: text.clone().into_owned() })?;
        out.push(Budget { bytes, source: BudgetSource::Variable });
    } else if let Some(bytes) = std::fs::read_to_string("/proc/meminfo").ok().and_then(|t| mem_available(&t)) {
        out.push(Budget { bytes, source: BudgetSource::MemAvailable });
    }
    if let Some(bytes) = cgroup_headroom() {
        out.push(Budget { bytes, source: BudgetSource::Cgroup });
    }
    if let Some(bytes) = address_space_headroom() {
        out.push(Budget { bytes, source: BudgetSource::AddressSpace });
    }
    Ok(out)
}

/// The memory budget: the smallest of [`budgets`]; `None` where there is none (then nothing is
/// refused for lack of memory).
///
/// # Errors
/// [`MemoryError::BadLimit`] when the variable is set but is not a size.
pub fn available_bytes() -> Result<Option<Budget>, MemoryError> {
    Ok(budgets()?.into_iter().min_by_key(|b| b.bytes))
}

/// Refuses a job that needs `needed` bytes when the budget is smaller.
///
/// # Errors
/// [`MemoryError::TooBig`] naming `what` with both figures and `advice`;
/// [`MemoryError::BadLimit`] as [`available_bytes`].
pub fn check(what: impl FnOnce() -> String, needed: u64, advice: &str) -> Result<(), MemoryError> {
    check_more(what, 0, needed, advice)
}

/// Refuses the next part of a job that is built piece by piece (the meshes of a scene): `more`
/// bytes on top of `already` bytes allocated for it so far. Against the figures read now
/// (`MemAvailable`, the cgroup's and the address space's headroom), which already account for
/// what was allocated, only `more` counts; against [`LIMIT_VAR`], a fixed budget, the sum does.
///
/// # Errors
/// As [`check`], with the figure that was compared.
pub fn check_more(what: impl FnOnce() -> String, already: u64, more: u64, advice: &str) -> Result<(), MemoryError> {
    let over = budgets()?
        .into_iter()
        .map(|b| (if b.source.is_fixed() { already.saturating_add(more) } else { more }, b))
        .filter(|(needed, b)| *needed > b.bytes)
        .min_by_key(|(_, b)| b.bytes);
    match over {
        Some((needed, b)) => Err(MemoryError::TooBig {
            what: what(),
            needed,
            available: b.bytes,
            from: b.source,
            advice: advice.to_owned(),
        }),
        None => Ok(()),
    }
}

/// `MemAvailable` from the text of `/proc/meminfo`, in bytes.
fn mem_available(meminfo: &str) -> Option<u64> {
    let line = meminfo.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let mut parts = line.split_whitespace().skip(1);
    let kib: u64 = parts.next()?.parse().ok()?;
    kib.checked_mul(1024)
}

/// Address space kept free under `RLIMIT_AS` for what is not a job's buffers: each thread
/// started later reserves a stack and glibc a malloc arena of 64 MiB (two in the worst case
/// for threads that allocate), per possible thread.
fn address_space_margin() -> u64 {
    let threads = std::thread::available_parallelism().map_or(2, std::num::NonZero::get) as u64 + 2;
    threads.saturating_mul(136 << 20).saturating_add(256 << 20)
}

/// The headroom under the address-space limit: the soft "Max address space" of
/// `/proc/self/limits` less `VmSize` of `/proc/self/status` and [`address_space_margin`];
/// `None` when unlimited or unreadable.
fn address_space_headroom() -> Option<u64> {
    let limit = address_space_limit(&std::fs::read_to_string("/proc/self/limits").ok()?)?;
    let size = vm_size(&std::fs::read_to_string("/proc/self/status").ok()?)?;
    Some(limit.saturating_sub(size).saturating_sub(address_space_margin()))
}

/// The soft limit of "Max address space" in the text of `/proc/self/limits`, in bytes; `None`
/// when unlimited.
fn address_space_limit(limits: &str) -> Option<u64> {
    let line = limits.lines().find(|l| l.starts_with("Max address space"))?;
    line["Max address space".len()..].split_whitespace().next()?.parse().ok()
}

/// `VmSize` from the text of `/proc/self/status`, in bytes.
fn vm_size(status: &str) -> Option<u64> {
    let line = status.lines().find(|l| l.starts_with("VmSize:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// Limits at or above this are "no limit" (cgroup v1 writes one of about 2^63 rounded to pages).
const NO_CGROUP_LIMIT: u64 = 1 << 60;

/// The headroom under the memory limits of the process's cgroup and its parents (v2 or v1);
/// `None` without a limit or a readable cgroup file system.
fn cgroup_headroom() -> Option<u64> {
    let cgroups = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    let mounts = std::fs::read_to_string("/proc/self/mountinfo").ok()?;
    let read = |p: &std::path::Path| std::fs::read_to_string(p).ok();
    let mut best: Option<u64> = None;
    for (dir, top, v2) in cgroup_dirs(&cgroups, &mounts) {
        let (limit_file, usage_file) =
            if v2 { ("memory.max", "memory.current") } else { ("memory.limit_in_bytes", "memory.usage_in_bytes") };
        let mut at = dir.as_path();
        loop {
            let limit = read(&at.join(limit_file)).and_then(|t| t.trim().parse::<u64>().ok());
            if let Some(limit) = limit.filter(|&l| l < NO_CGROUP_LIMIT) {
                let usage = read(&at.join(usage_file)).and_then(|t| t.trim().parse::<u64>().ok()).unwrap_or(0);
                let room = limit.saturating_sub(usage);
                best = Some(best.map_or(room, |b| b.min(room)));
            }
            if at == top.as_path() {
                break;
            }
            match at.parent() {
                Some(p) if p.starts_with(&top) => at = p,
                _ => break,
            }
        }
    }
    best
}

/// The directories of the process's memory cgroups, from the texts of `/proc/self/cgroup` and
/// `/proc/self/mountinfo`: `(its directory, the mount point above which not to look, v2)`.
/// A cgroup outside the mount's root (a namespace shows its own root) is the mount point itself.
fn cgroup_dirs(cgroups: &str, mountinfo: &str) -> Vec<(std::path::PathBuf, std::path::PathBuf, bool)> {
    use std::path::{Path, PathBuf};
    let mut out = Vec::new();
    for line in cgroups.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(id), Some(controllers), Some(path)) = (parts.next(), parts.next(), parts.next()) else { continue };
        let v2 = id == "0" && controllers.is_empty();
        if !v2 && !controllers.split(',').any(|c| c == "memory") {
            continue;
        }
        for m in mountinfo.lines() {
            // ID PARENT MAJ:MIN ROOT MOUNT_POINT OPTIONS [OPTIONAL...] - FSTYPE SOURCE SUPER_OPTIONS
            let Some((left, right)) = m.split_once(" - ") else { continue };
            let fields: Vec<&str> = left.split(' ').collect();
            let right: Vec<&str> = right.split(' ').collect();
            let (Some(root), Some(point), Some(fs)) = (fields.get(3), fields.get(4), right.first()) else { continue };
            let fits = if v2 {
                *fs == "cgroup2"
            } else {
                *fs == "cgroup" && right.get(2).is_some_and(|o| o.split(',').any(|c| c == "memory"))
            };
            if !fits {
                continue;
            }
            let point = PathBuf::from(point.replace("\\040", " "));
            let dir = match Path::new(path).strip_prefix(root) {
                Ok(rel) if !rel.as_os_str().is_empty() => point.join(rel),
                _ => point.clone(),
            };
            let dir = if dir.is_dir() { dir } else { point.clone() };
            out.push((dir, point, v2));
            break;
        }
    }
    out
}

/// Parses a memory size: `123`, `4GiB`, `512 MiB`, `2G`, `1.5GiB`, `3GB` (decimal).
#[must_use]
pub fn parse_size(s: &str) -> Option<u64> {
    let s = s.trim();
    let split = s.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(s.len());
    let (number, unit) = s.split_at(split);
    let number: f64 = number.parse().ok()?;
    let scale: f64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "k" | "kib" => 1024.0,
        "m" | "mib" => 1024.0 * 1024.0,
        "g" | "gib" => 1024.0 * 1024.0 * 1024.0,
        "t" | "tib" => 1024.0 * 1024.0 * 1024.0 * 1024.0,
        "kb" => 1e3,
        "mb" => 1e6,
        "gb" => 1e9,
        "tb" => 1e12,
        _ => return None,
    };
    let bytes = number * scale;
    (0.0..1.8e19).contains(&bytes).then_some(bytes as u64)
}

/// A byte count for people: `512 B`, `3.2 MiB`, `14.2 GiB`.
#[must_use]
pub fn format_bytes(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = bytes as f64;
    let mut unit = 0;
    while v >= 1024.0 && unit + 1 < UNITS.len() {
        v /= 1024.0;
        unit += 1;
    }
    if unit == 0 { format!("{bytes} B") } else { format!("{v:.1} {}", UNITS[unit]) }
}

/// A vector of `n` copies of `value`, or the allocator's refusal instead of an abort.
///
/// # Errors
/// The [`TryReserveError`] when `n` elements cannot be allocated.
pub fn try_vec<T: Clone>(value: T, n: usize) -> Result<Vec<T>, TryReserveError> {
    let mut v = Vec::new();
    v.try_reserve_exact(n)?;
    v.resize(n, value);
    Ok(v)
}

/// The bytes `n` values of `T` take.
#[must_use]
pub fn bytes_of<T>(n: u64) -> u64 {
    n.saturating_mul(std::mem::size_of::<T>() as u64)
}

/// A job's memory estimate: named parts, summed.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Estimate {
    /// `(what, bytes)` per part.
    pub parts: Vec<(String, u64)>,
}

impl Estimate {
    /// Adds a part.
    pub fn add(&mut self, what: impl Into<String>, bytes: u64) {
        self.parts.push((what.into(), bytes));
    }

    /// The bytes of the parts whose names start with `prefix`.
    #[must_use]
    pub fn part(&self, prefix: &str) -> u64 {
        self.parts.iter().filter(|(w, _)| w.starts_with(prefix)).fold(0u64, |a, (_, b)| a.saturating_add(*b))
    }

    /// The sum of every part.
    #[must_use]
    pub fn total(&self) -> u64 {
        self.parts.iter().fold(0u64, |a, (_, b)| a.saturating_add(*b))
    }

    /// Refuses the job when [`Estimate::total`] exceeds the budget (see [`check`]).
    ///
    /// # Errors
    /// As [`check`].
    pub fn check(&self, what: impl FnOnce() -> String, advice: &str) -> Result<(), MemoryError> {
        check(what, self.total(), advice)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_with_units() {
        assert_eq!(parse_size("4GiB"), Some(4 << 30));
        assert_eq!(parse_size("512 MiB"), Some(512 << 20));
        assert_eq!(parse_size("2g"), Some(2 << 30));
        assert_eq!(parse_size("1000"), Some(1000));
        assert_eq!(parse_size("3GB"), Some(3_000_000_000));
        assert_eq!(parse_size("1.5KiB"), Some(1536));
        assert_eq!(parse_size("lots"), None);
        assert_eq!(parse_size("-1G"), None);
        assert_eq!(parse_size("4 parsecs"), None);
    }

    #[test]
    fn meminfo_is_read_in_kib() {
        let text = "MemTotal:       24576000 kB\nMemFree:  100 kB\nMemAvailable:   9437184 kB\n";
        assert_eq!(mem_available(text), Some(9437184 * 1024));
        assert_eq!(mem_available("MemTotal: 5 kB\n"), None);
    }

    #[test]
    fn the_address_space_limit_and_size_are_read_in_bytes() {
        let limits = "Limit                     Soft Limit           Hard Limit           Units     \n\
                      Max stack size            8388608              unlimited            bytes     \n\
                      Max address space         4294967296           unlimited            bytes     \n";
        assert_eq!(address_space_limit(limits), Some(4 << 30));
        assert_eq!(address_space_limit("Max address space         unlimited            unlimited   bytes\n"), None);
        assert_eq!(vm_size("Name:\tpomkit\nVmPeak:\t  9000 kB\nVmSize:\t    3892 kB\n"), Some(3892 * 1024));
    }

    #[test]
    fn the_memory_cgroup_is_found_from_its_mount() {
        let mounts = "35 31 0:32 / /sys/fs/cgroup/memory rw,relatime - cgroup cgroup rw,memory\n\
                      41 31 0:38 / /sys/fs/cgroup/unified rw,relatime - cgroup2 cgroup2 rw\n\
                      32 31 0:29 / /sys/fs/cgroup/cpu rw,relatime - cgroup cgroup rw,cpu\n";
        // v1: the memory controller's line; a path the mount does not show is the mount itself.
        let dirs = cgroup_dirs("4:memory:/no/such/group\n1:cpu:/\n", mounts);
        let memory = std::path::PathBuf::from("/sys/fs/cgroup/memory");
        assert_eq!(dirs, vec![(memory.clone(), memory, false)]);
        // v2: the unified line, under the cgroup2 mount.
        let v2 = cgroup_dirs("0::/\n", mounts);
        let unified = std::path::PathBuf::from("/sys/fs/cgroup/unified");
        assert_eq!(v2, vec![(unified.clone(), unified, true)]);
        assert!(cgroup_dirs("1:cpu:/\n", mounts).is_empty());
    }

    #[test]
    fn the_smallest_budget_is_named_and_a_fixed_one_counts_what_is_held() {
        assert!(BudgetSource::Variable.is_fixed() && !BudgetSource::AddressSpace.is_fixed());
        let e = MemoryError::TooBig {
            what: "render of 4096x4096 on the GPU".into(),
            needed: 3 << 30,
            available: 1 << 30,
            from: BudgetSource::AddressSpace,
            advice: "use a smaller --size".into(),
        };
        assert!(e.to_string().contains("1.0 GiB is available (the address-space limit, ulimit -v)"), "{e}");
        let MemoryError::TooBig { what, needed, available, advice, .. } = e else { unreachable!() };
        let c = MemoryError::TooBig { what, needed, available, from: BudgetSource::Cgroup, advice };
        assert!(c.to_string().contains("(the cgroup's memory limit)"), "{c}");
    }

    #[test]
    fn bytes_print_in_binary_units() {
        assert_eq!(format_bytes(512), "512 B");
        assert_eq!(format_bytes(3 << 20), "3.0 MiB");
        assert_eq!(format_bytes(15_246_925_824), "14.2 GiB");
    }

    #[test]
    fn the_message_gives_both_figures_and_the_advice() {
        let e = MemoryError::TooBig {
            what: "render of 16384x16384".into(),
            needed: 15_246_925_824,
            available: 9_771_050_598,
            from: BudgetSource::MemAvailable,
            advice: "use a smaller --size".into(),
        };
        assert_eq!(
            e.to_string(),
            "render of 16384x16384 needs about 14.2 GiB; 9.1 GiB is available (MemAvailable): use a smaller --size"
        );
    }

    #[test]
    fn try_vec_refuses_instead_of_aborting() {
        assert!(try_vec(0u64, usize::MAX / 4).is_err());
        assert_eq!(try_vec(7u8, 3).unwrap(), vec![7, 7, 7]);
    }
}
