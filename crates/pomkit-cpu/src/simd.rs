//! The SIMD level the CPU renderer shades its packets of eight fragments with.
//!
//! The packets are written once over [`fearless_simd`]'s eight-lane vectors and dispatched at
//! run time: AVX2 (with FMA available, though the packets use none, so that every lane rounds as
//! the scalar code does), SSE4.2 (each vector as two halves), NEON on 64-bit ARM (two halves),
//! or the crate's scalar fallback. fearless_simd has no AVX-512 level: an AVX-512 CPU runs the
//! AVX2 code. Every level gives the same picture, bit for bit; `POMKIT_SIMD=scalar` forces the
//! fallback (CI runs the picture tests both ways).

use fearless_simd::Level;

/// The environment variable that chooses the level: `auto` (or unset) for the best this CPU
/// has, `scalar` for the portable fallback.
pub const SIMD_ENV: &str = "POMKIT_SIMD";

/// A SIMD level for the CPU renderer's packets.
#[derive(Clone, Copy, Debug)]
pub struct Simd8 {
    pub(crate) level: Level,
    /// Packets of eight fragments (else one fragment at a time, the scalar reference).
    pub(crate) packets: bool,
}

/// `POMKIT_SIMD` holds a value the renderer does not know.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "{SIMD_ENV}={0:?} is not a SIMD level: expected auto (the best this CPU has) or scalar (the portable fallback)"
)]
pub struct SimdEnvError(pub String);

impl Simd8 {
    /// The best level this CPU has.
    #[must_use]
    pub fn detect() -> Self {
        Self { level: Level::new(), packets: true }
    }

    /// The scalar fallback: the same packets on arrays of eight floats, no target features.
    #[must_use]
    pub fn scalar() -> Self {
        Self { level: Level::fallback(), packets: true }
    }

    /// The level `POMKIT_SIMD` asks for: `auto` or unset gives [`Simd8::detect`], `scalar`
    /// gives [`Simd8::scalar`] (case-insensitive, surrounding blanks ignored).
    ///
    /// # Errors
    /// [`SimdEnvError`] for any other value, naming it.
    pub fn from_env() -> Result<Self, SimdEnvError> {
        match std::env::var(SIMD_ENV) {
            Err(_) => Ok(Self::detect()),
            Ok(v) => match v.trim().to_ascii_lowercase().as_str() {
                "" | "auto" => Ok(Self::detect()),
                "scalar" => Ok(Self::scalar()),
                _ => Err(SimdEnvError(v)),
            },
        }
    }

    /// No packets: every fragment shaded on its own by the scalar code, the reference the
    /// packets are tested against (and the slowest way).
    #[must_use]
    pub fn unpacked() -> Self {
        Self { level: Level::fallback(), packets: false }
    }

    /// The level's name: `avx2`, `sse4.2`, `neon`, `scalar`, or `unpacked` for
    /// [`Simd8::unpacked`].
    #[must_use]
    pub fn name(&self) -> &'static str {
        if !self.packets {
            return "unpacked";
        }
        if self.level.is_fallback() {
            return "scalar";
        }
        #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
        {
            if self.level.as_avx2().is_some() {
                return "avx2";
            }
            if self.level.as_sse4_2().is_some() {
                return "sse4.2";
            }
        }
        #[cfg(target_arch = "aarch64")]
        if self.level.as_neon().is_some() {
            return "neon";
        }
        "scalar"
    }

    /// Whether this is the scalar fallback (or no packets at all).
    #[must_use]
    pub fn is_scalar(&self) -> bool {
        self.level.is_fallback()
    }
}

/// The SIMD features this CPU reports that matter to the renderer, space-separated (for
/// benchmark reports): on x86-64 any of `sse4.2 avx2 fma avx512f`, on ARM `neon`.
#[must_use]
pub fn cpu_features() -> String {
    let mut found: Vec<&str> = Vec::new();
    #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
    {
        if std::arch::is_x86_feature_detected!("sse4.2") {
            found.push("sse4.2");
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            found.push("avx2");
        }
        if std::arch::is_x86_feature_detected!("fma") {
            found.push("fma");
        }
        if std::arch::is_x86_feature_detected!("avx512f") {
            found.push("avx512f");
        }
    }
    #[cfg(target_arch = "aarch64")]
    if std::arch::is_aarch64_feature_detected!("neon") {
        found.push("neon");
    }
    if found.is_empty() { "none".to_owned() } else { found.join(" ") }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_levels_are_named_and_the_fallback_is_scalar() {
        assert_eq!(Simd8::scalar().name(), "scalar");
        assert!(Simd8::scalar().is_scalar());
        let best = Simd8::detect();
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
            assert_eq!(best.name(), "avx2");
        }
        assert!(!cpu_features().is_empty());
        let err = SimdEnvError("avx9".into()).to_string();
        assert!(err.contains("POMKIT_SIMD=\"avx9\"") && err.contains("scalar"), "{err}");
    }
}
