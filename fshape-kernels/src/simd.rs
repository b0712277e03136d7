//! Which instruction set the vectorised sums run on.
//!
//! By default the best the CPU has (pulp's runtime detection: AVX-512, then
//! AVX2, then none). The environment variable `FSHAPE_SIMD` caps it, so
//! that a figure measured on an AVX2 machine (most users' CPUs) can be
//! reproduced on an AVX-512 one: `avx2` (at most AVX2), `scalar` (no
//! SIMD), `auto` or unset (the best). It is read once per process.
//!
//! Every vectorised path holds its lanes in fixed `[f64; L]` blocks and
//! rounds each fused multiply-add once (`f64::mul_add`), so the order of
//! every operation is the same on every instruction set: the choice
//! changes the time, never the bits (tested on the instruction sets the
//! machine has).

use std::sync::OnceLock;

use pulp::Arch;

/// The environment variable that caps the instruction set.
pub const ENV: &str = "FSHAPE_SIMD";

/// What `FSHAPE_SIMD` asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cap {
    /// The best the CPU has.
    Auto,
    /// AVX2 (4 f64 lanes) at most.
    Avx2,
    /// No SIMD: the portable scalar code.
    Scalar,
}

impl Cap {
    /// Parses a value of `FSHAPE_SIMD` (case and surrounding blanks
    /// ignored; empty is `auto`).
    pub fn parse(text: &str) -> Result<Cap, String> {
        match text.trim().to_ascii_lowercase().as_str() {
            "" | "auto" => Ok(Cap::Auto),
            "avx2" => Ok(Cap::Avx2),
            "scalar" => Ok(Cap::Scalar),
            other => Err(format!("{ENV}={other:?}: expected auto, avx2 or scalar")),
        }
    }

    /// The cap the environment sets: `Auto` when unset, an error naming
    /// the variable when its value is not one of the three.
    pub fn from_env() -> Result<Cap, String> {
        match std::env::var(ENV) {
            Ok(v) => Cap::parse(&v),
            Err(std::env::VarError::NotPresent) => Ok(Cap::Auto),
            Err(std::env::VarError::NotUnicode(_)) => Err(format!("{ENV}: not valid UTF-8")),
        }
    }

    /// The instruction set under this cap on this CPU.
    pub fn arch(self) -> Arch {
        match self {
            Cap::Auto => Arch::new(),
            Cap::Scalar => Arch::Scalar,
            Cap::Avx2 => avx2_at_most(),
        }
    }
}

#[cfg(target_arch = "x86_64")]
fn avx2_at_most() -> Arch {
    pulp::x86::V3::try_new().map_or(Arch::Scalar, Arch::V3)
}

#[cfg(not(target_arch = "x86_64"))]
fn avx2_at_most() -> Arch {
    // No AVX-512 elsewhere: the cap changes nothing.
    Arch::new()
}

/// The instruction set the sums use in this process (see the module): the
/// cap `FSHAPE_SIMD` sets, read once; a value that is not understood
/// counts as unset here (the program refuses it at its start, naming it).
pub fn arch() -> Arch {
    static ARCH: OnceLock<Arch> = OnceLock::new();
    *ARCH.get_or_init(|| Cap::from_env().unwrap_or(Cap::Auto).arch())
}

/// A name for an instruction set, for reports: `avx512`, `avx2` or
/// `scalar`.
pub fn name(arch: Arch) -> &'static str {
    #[cfg(target_arch = "x86_64")]
    {
        match arch {
            Arch::V4(_) => "avx512",
            Arch::V3(_) => "avx2",
            _ => "scalar",
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        match arch {
            Arch::Scalar => "scalar",
            _ => "simd",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cap_is_parsed_and_never_raises_the_instruction_set() {
        assert_eq!(Cap::parse(" AVX2 "), Ok(Cap::Avx2));
        assert_eq!(Cap::parse(""), Ok(Cap::Auto));
        assert_eq!(Cap::parse("scalar"), Ok(Cap::Scalar));
        let e = Cap::parse("avx-512").unwrap_err();
        assert!(e.contains("FSHAPE_SIMD") && e.contains("avx-512"), "{e}");
        assert_eq!(name(Cap::Scalar.arch()), "scalar");
        assert_ne!(name(Cap::Avx2.arch()), "avx512");
        // The cap is at most what the CPU has.
        let best = name(Cap::Auto.arch());
        let capped = name(Cap::Avx2.arch());
        assert!(best == capped || (best == "avx512" && capped == "avx2"), "{best} {capped}");
    }
}
