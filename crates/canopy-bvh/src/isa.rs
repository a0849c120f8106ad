//! Which SIMD instruction set the traversal kernels use, detected once at run time.
//!
//! canopy is built for baseline x86-64 (or any other target) and picks its kernels when a
//! tree is made, so one binary runs everywhere and still uses AVX2 or AVX-512 where the
//! CPU has them. Every kernel has a scalar twin with the same arithmetic; tests run each
//! twin the machine supports on the same rays and demand identical answers.

use std::fmt;
use std::str::FromStr;

/// An instruction set that traversal kernels exist for, from the most portable up.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Isa {
    /// Plain Rust, on every target: the reference twin.
    Scalar,
    /// 4-lane SSE2, part of baseline x86-64.
    Sse2,
    /// 8-lane AVX2.
    Avx2,
    /// AVX-512 (F and VL): 8 lanes with mask registers.
    Avx512,
}

impl Isa {
    pub const ALL: [Isa; 4] = [Isa::Scalar, Isa::Sse2, Isa::Avx2, Isa::Avx512];

    /// The best instruction set this CPU supports.
    pub fn best() -> Isa {
        *Isa::supported().last().expect("scalar is always supported")
    }

    /// Every instruction set this CPU supports, from the most portable up.
    pub fn supported() -> Vec<Isa> {
        Isa::ALL
            .into_iter()
            .filter(|isa| isa.is_supported())
            .collect()
    }

    pub fn is_supported(self) -> bool {
        match self {
            Isa::Scalar => true,
            #[cfg(target_arch = "x86_64")]
            Isa::Sse2 => true,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => std::arch::is_x86_feature_detected!("avx2"),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => {
                std::arch::is_x86_feature_detected!("avx512f")
                    && std::arch::is_x86_feature_detected!("avx512vl")
            }
            #[cfg(not(target_arch = "x86_64"))]
            _ => false,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Isa::Scalar => "scalar",
            Isa::Sse2 => "sse2",
            Isa::Avx2 => "avx2",
            Isa::Avx512 => "avx512",
        }
    }
}

impl fmt::Display for Isa {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// An instruction set that is unknown by name or that this CPU lacks.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum IsaError {
    #[error("unknown instruction set `{0}` (known: scalar, sse2, avx2, avx512)")]
    Unknown(String),
    #[error("this CPU does not support {0}")]
    Unsupported(Isa),
}

impl FromStr for Isa {
    type Err = IsaError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Isa::ALL
            .into_iter()
            .find(|isa| isa.name() == s)
            .ok_or_else(|| IsaError::Unknown(s.to_owned()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalar_is_always_supported_and_best_is_supported() {
        assert!(Isa::Scalar.is_supported());
        assert!(Isa::best().is_supported());
        assert_eq!(Isa::supported()[0], Isa::Scalar);
    }

    #[test]
    fn names_round_trip() {
        for isa in Isa::ALL {
            assert_eq!(isa.name().parse::<Isa>(), Ok(isa));
        }
        assert!("neon".parse::<Isa>().is_err());
    }
}
