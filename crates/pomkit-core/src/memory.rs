//! The memory budget every job is checked against before it starts, and the largest image side
//! pomkit handles (docs/LIMITS.md).
//!
//! A job (a render, a displaced mesh, a decoded image) first sums the big buffers it will
//! allocate and compares the sum with [`available_bytes`]: on Linux the kernel's `MemAvailable`
//! (from `/proc/meminfo`), or the value of the environment variable [`LIMIT_VAR`]
//! (`POMKIT_MEMORY_LIMIT=4GiB`) when it is set. A job that will not fit is refused up front with a
//! [`MemoryError`] that gives both figures and what to change, rather than aborting half-way
//! through with the allocator's "memory allocation of N bytes failed". Elsewhere (no
//! `/proc/meminfo`, no variable) nothing is refused on this basis.
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
}

impl fmt::Display for BudgetSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BudgetSource::Variable => write!(f, "{LIMIT_VAR}"),
            BudgetSource::MemAvailable => f.write_str("MemAvailable"),
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

/// The memory budget: [`LIMIT_VAR`] when set, else `MemAvailable` on Linux; `None` where
/// neither exists (then nothing is refused for lack of memory).
///
/// # Errors
/// [`MemoryError::BadLimit`] when the variable is set but is not a size.
pub fn available_bytes() -> Result<Option<Budget>, MemoryError> {
    if let Some(value) = std::env::var_os(LIMIT_VAR) {
        let text = value.to_string_lossy();
        let bytes = parse_size(&text).ok_or_else(|| MemoryError::BadLimit { value: text.clone().into_owned() })?;
        return Ok(Some(Budget { bytes, source: BudgetSource::Variable }));
    }
    Ok(std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|text| mem_available(&text))
        .map(|bytes| Budget { bytes, source: BudgetSource::MemAvailable }))
}

/// Refuses a job that needs `needed` bytes when the budget is smaller.
///
/// # Errors
/// [`MemoryError::TooBig`] naming `what` with both figures and `advice`;
/// [`MemoryError::BadLimit`] as [`available_bytes`].
pub fn check(what: impl FnOnce() -> String, needed: u64, advice: &str) -> Result<(), MemoryError> {
    match available_bytes()? {
        Some(b) if needed > b.bytes => Err(MemoryError::TooBig {
            what: what(),
            needed,
            available: b.bytes,
            from: b.source,
            advice: advice.to_owned(),
        }),
        _ => Ok(()),
    }
}

/// Refuses the next part of a job that is built piece by piece (the meshes of a scene): `more`
/// bytes on top of `already` bytes allocated for it so far. Against `MemAvailable`, which
/// already accounts for what was allocated, only `more` counts; against [`LIMIT_VAR`], a fixed
/// budget, the sum does.
///
/// # Errors
/// As [`check`], with the figure that was compared.
pub fn check_more(what: impl FnOnce() -> String, already: u64, more: u64, advice: &str) -> Result<(), MemoryError> {
    let Some(b) = available_bytes()? else { return Ok(()) };
    let needed = match b.source {
        BudgetSource::Variable => already.saturating_add(more),
        BudgetSource::MemAvailable => more,
    };
    if needed > b.bytes {
        return Err(MemoryError::TooBig {
            what: what(),
            needed,
            available: b.bytes,
            from: b.source,
            advice: advice.to_owned(),
        });
    }
    Ok(())
}

/// The budget in bytes, or `u64::MAX` when there is none (for limits passed to other libraries).
///
/// # Errors
/// As [`available_bytes`].
pub fn budget_or_unlimited() -> Result<u64, MemoryError> {
    Ok(available_bytes()?.map_or(u64::MAX, |b| b.bytes))
}

/// `MemAvailable` from the text of `/proc/meminfo`, in bytes.
fn mem_available(meminfo: &str) -> Option<u64> {
    let line = meminfo.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let mut parts = line.split_whitespace().skip(1);
    let kib: u64 = parts.next()?.parse().ok()?;
    kib.checked_mul(1024)
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
