//! What the CPU offers this crate's kernels: the vector levels and the
//! dispatch macro of `fmaps-simd` (the workspace's one dispatch layer),
//! and the matrix tiles (AMX, detected in `tiles`).
//!
//! Every level runs the same code, so computes the same values: no FMA
//! contraction, the same summation order (kernels written with intrinsics
//! say where they differ).

pub(crate) use fmaps_simd::dispatched;
pub use fmaps_simd::{SimdLevel, set_simd_cap, simd_level};
#[cfg(target_arch = "x86_64")]
pub(crate) use fmaps_simd::{has_v3, has_v4};

/// What this CPU (and OS) offers the kernels of this crate, within the
/// cap of [`set_simd_cap`] / `FMAPS_SIMD`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub struct CpuFeatures {
    /// AVX-512 F, BW and VL, with AVX2 and FMA (x86-64-v4).
    pub avx512: bool,
    /// AVX2 with FMA, BMI1/2, POPCNT and LZCNT (x86-64-v3).
    pub avx2: bool,
    /// Intel AMX matrix tiles with bf16 (AMX-TILE, AMX-BF16, the OS's
    /// permission for the tile state) and `FMAPS_NO_AMX` unset.
    pub amx: bool,
}

impl std::fmt::Display for CpuFeatures {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let level = if self.avx512 {
            "AVX-512"
        } else if self.avx2 {
            "AVX2+FMA"
        } else {
            "baseline"
        };
        let amx = if self.amx { "AMX yes" } else { "AMX no" };
        write!(f, "{level}, {amx}")
    }
}

/// The features detected here (cached after the first call).
pub fn cpu_features() -> CpuFeatures {
    let level = simd_level();
    let (avx512, avx2) = (level >= SimdLevel::Avx512, level >= SimdLevel::Avx2);
    CpuFeatures {
        avx512,
        avx2,
        amx: crate::tiles::available(),
    }
}
