//! The one place where the CPU's vector and matrix extensions are
//! detected (once per process), and the macro that compiles a kernel for
//! each level and runs the widest one the CPU has. The crates build for
//! baseline x86-64 (SSE2); faer's GEMMs dispatch on their own.
//!
//! Every level runs the same code, so computes the same values: no FMA
//! contraction, the same summation order (kernels written with intrinsics
//! say where they differ).

use std::sync::OnceLock;

/// What this CPU (and OS) offers the kernels of this crate.
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
    #[cfg(target_arch = "x86_64")]
    let (avx512, avx2) = (has_v4(), has_v3());
    #[cfg(not(target_arch = "x86_64"))]
    let (avx512, avx2) = (false, false);
    CpuFeatures {
        avx512,
        avx2,
        amx: crate::tiles::available(),
    }
}

/// A function compiled three times, for AVX-512, for AVX2 and for baseline
/// x86-64, and the widest one the CPU has run (see [`has_v4`], [`has_v3`]).
macro_rules! dispatched {
    ($(#[$m:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) -> $ret:ty $body:block) => {
        $(#[$m])*
        $vis fn $name($($arg: $ty),*) -> $ret {
            #[inline(always)]
            fn body($($arg: $ty),*) -> $ret $body
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma,bmi1,bmi2,popcnt,lzcnt")]
                fn v4($($arg: $ty),*) -> $ret {
                    body($($arg),*)
                }
                #[target_feature(enable = "avx2,fma,bmi1,bmi2,popcnt,lzcnt")]
                fn v3($($arg: $ty),*) -> $ret {
                    body($($arg),*)
                }
                if $crate::cpu::has_v4() {
                    // SAFETY: the CPU has the features (runtime check).
                    return unsafe { v4($($arg),*) };
                }
                if $crate::cpu::has_v3() {
                    // SAFETY: as above.
                    return unsafe { v3($($arg),*) };
                }
            }
            body($($arg),*)
        }
    };
}

pub(crate) use dispatched;

/// AVX-512 (F, BW, VL) with AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
pub(crate) fn has_v4() -> bool {
    static V4: OnceLock<bool> = OnceLock::new();
    *V4.get_or_init(|| {
        std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512bw")
            && std::arch::is_x86_feature_detected!("avx512vl")
            && has_v3()
    })
}

/// AVX2 with FMA, BMI and the bit-count instructions.
#[cfg(target_arch = "x86_64")]
pub(crate) fn has_v3() -> bool {
    static V3: OnceLock<bool> = OnceLock::new();
    *V3.get_or_init(|| {
        std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
            && std::arch::is_x86_feature_detected!("bmi1")
            && std::arch::is_x86_feature_detected!("bmi2")
            && std::arch::is_x86_feature_detected!("popcnt")
            && std::arch::is_x86_feature_detected!("lzcnt")
    })
}
