//! The one place where the CPU's vector and matrix extensions are
//! detected (once per process), and the macro that compiles a kernel for
//! each level and runs the widest one the CPU has. The crates build for
//! baseline x86-64 (SSE2); faer's GEMMs dispatch on their own.
//!
//! Every level runs the same code, so computes the same values: no FMA
//! contraction, the same summation order (kernels written with intrinsics
//! say where they differ).

#[cfg(target_arch = "x86_64")]
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU8, Ordering};

/// An instruction-set level of the kernels, narrowest first.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum SimdLevel {
    /// Baseline code (x86-64: SSE2; other targets: what the compiler
    /// targets by default).
    Baseline,
    /// AVX2 with FMA, BMI1/2, POPCNT and LZCNT (x86-64-v3).
    Avx2,
    /// AVX-512 F, BW and VL on top of AVX2 (x86-64-v4).
    Avx512,
}

impl SimdLevel {
    /// Every level, narrowest first.
    pub const ALL: [SimdLevel; 3] = [SimdLevel::Baseline, SimdLevel::Avx2, SimdLevel::Avx512];

    /// Its name in `FMAPS_SIMD` ("baseline", "avx2", "avx512").
    pub fn name(self) -> &'static str {
        match self {
            SimdLevel::Baseline => "baseline",
            SimdLevel::Avx2 => "avx2",
            SimdLevel::Avx512 => "avx512",
        }
    }

    /// Whether this CPU has the level (whatever the cap).
    pub fn detected(self) -> bool {
        match self {
            SimdLevel::Baseline => true,
            #[cfg(target_arch = "x86_64")]
            SimdLevel::Avx2 => detected_v3(),
            #[cfg(target_arch = "x86_64")]
            SimdLevel::Avx512 => detected_v4(),
            #[cfg(not(target_arch = "x86_64"))]
            _ => false,
        }
    }
}

/// The cap as set (`u8::MAX`: none yet; read `FMAPS_SIMD` on first use).
static CAP: AtomicU8 = AtomicU8::new(u8::MAX);
const NO_CAP: u8 = SimdLevel::Avx512 as u8;

/// The widest level the kernels may use: `FMAPS_SIMD` (baseline, avx2 or
/// avx512; unset or anything else: no cap) unless [`set_simd_cap`] was
/// called.
fn cap() -> u8 {
    let c = CAP.load(Ordering::Relaxed);
    if c != u8::MAX {
        return c;
    }
    let from_env = std::env::var("FMAPS_SIMD")
        .ok()
        .and_then(|v| SimdLevel::ALL.into_iter().find(|l| l.name() == v))
        .map_or(NO_CAP, |l| l as u8);
    // Another thread may have set a cap meanwhile: keep it.
    let _ = CAP.compare_exchange(u8::MAX, from_env, Ordering::Relaxed, Ordering::Relaxed);
    CAP.load(Ordering::Relaxed)
}

/// Caps the instruction set of this crate's kernels at `level` for the
/// whole process (`None`: no cap), e.g. to test or time the AVX2 or the
/// baseline kernels on an AVX-512 CPU; overrides `FMAPS_SIMD`. Results
/// do not depend on it (the searches are exact), only speed. faer's own
/// GEMMs dispatch on their own and are not affected.
pub fn set_simd_cap(level: Option<SimdLevel>) {
    CAP.store(level.map_or(NO_CAP, |l| l as u8), Ordering::Relaxed);
}

/// The level the kernels run at: the widest the CPU has, within the cap.
pub fn simd_level() -> SimdLevel {
    SimdLevel::ALL
        .into_iter()
        .rev()
        .find(|&l| l as u8 <= cap() && l.detected())
        .unwrap_or(SimdLevel::Baseline)
}

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

/// AVX-512 (F, BW, VL) with AVX2 and FMA, within the cap.
#[cfg(target_arch = "x86_64")]
pub(crate) fn has_v4() -> bool {
    cap() >= SimdLevel::Avx512 as u8 && detected_v4()
}

/// AVX2 with FMA, BMI and the bit-count instructions, within the cap.
#[cfg(target_arch = "x86_64")]
pub(crate) fn has_v3() -> bool {
    cap() >= SimdLevel::Avx2 as u8 && detected_v3()
}

/// Whether the CPU has AVX-512 (F, BW, VL) with AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
fn detected_v4() -> bool {
    static V4: OnceLock<bool> = OnceLock::new();
    *V4.get_or_init(|| {
        std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512bw")
            && std::arch::is_x86_feature_detected!("avx512vl")
            && detected_v3()
    })
}

/// Whether the CPU has AVX2 with FMA, BMI and the bit-count instructions.
#[cfg(target_arch = "x86_64")]
fn detected_v3() -> bool {
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
