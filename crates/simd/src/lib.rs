//! CPU-feature detection (once per process) and run-time dispatch for the
//! numeric kernels of the fmaps workspace.
//!
//! A kernel is written once, in plain Rust, as a [`Kernel`] (or a function
//! wrapped in [`dispatched!`]); it is compiled for AVX-512 (x86-64-v4), for
//! AVX2 with FMA (x86-64-v3) and for the baseline target, and [`dispatch`]
//! runs the widest level the CPU has, within the cap of [`set_simd_cap`] /
//! `FMAPS_SIMD`. The crates build for baseline x86-64 (SSE2); faer's GEMMs
//! dispatch on their own. On other targets (aarch64: NEON) the baseline
//! code runs, vectorized by the compiler for the target's vector unit.
//!
//! ```
//! use fmaps_simd::{Kernel, SimdLevel, dispatch};
//!
//! /// A dot product, its multiply-adds fused where the level has FMA.
//! struct Dot<'a>(&'a [f64], &'a [f64]);
//! impl Kernel for Dot<'_> {
//!     type Output = f64;
//!     #[inline(always)]
//!     fn run(self, level: SimdLevel) -> f64 {
//!         self.0.iter().zip(self.1).fold(0.0, |s, (a, b)| level.mul_add(*a, *b, s))
//!     }
//! }
//! assert_eq!(dispatch(Dot(&[1.0, 2.0], &[3.0, 4.0])), 11.0);
//! // Every level the CPU has can be forced, e.g. in a test:
//! for level in fmaps_simd::SimdLevel::ALL.into_iter().filter(|l| l.detected()) {
//!     fmaps_simd::set_simd_cap(Some(level));
//!     assert_eq!(fmaps_simd::simd_level(), level);
//! }
//! fmaps_simd::set_simd_cap(None);
//! ```
//!
//! The crate also holds the workspace's one deterministic random generator,
//! [`SplitMix`], as the leaf every numeric crate already depends on.
//!
//! Nothing here can fail, so the crate has no error type.

#![deny(missing_docs)]

mod rng;
mod wedge;
pub use rng::SplitMix;
pub use wedge::{Fan, wedge_sums};

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

    /// Whether kernels at this level fuse multiply-adds
    /// ([`SimdLevel::mul_add`]): AVX2 and AVX-512 have FMA; baseline x86-64
    /// has not (a fused multiply-add would be a slow library call there),
    /// aarch64's baseline has.
    #[inline(always)]
    pub fn fma(self) -> bool {
        match self {
            SimdLevel::Baseline => cfg!(target_arch = "aarch64"),
            SimdLevel::Avx2 | SimdLevel::Avx512 => true,
        }
    }

    /// `a · b + c`, fused (one rounding) where the level has FMA
    /// ([`SimdLevel::fma`]), else a product and a sum. Inside a
    /// [`Kernel`] the level is a constant, so the choice costs nothing.
    #[inline(always)]
    pub fn mul_add(self, a: f64, b: f64, c: f64) -> f64 {
        if self.fma() {
            a.mul_add(b, c)
        } else {
            a * b + c
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

/// Runs `f` at every level this CPU has (narrowest first), the
/// process-wide cap ([`set_simd_cap`]) set to it, then lifts the cap and
/// prints the levels the CPU lacks (a test that runs through here says
/// what it skipped). Under one lock for the process: tests run on
/// parallel threads, and one that compares results at a fixed level must
/// not see another change the level. Meant for tests.
///
/// ```
/// let mut seen = Vec::new();
/// fmaps_simd::at_every_level(|level| seen.push(level));
/// assert_eq!(seen[0], fmaps_simd::SimdLevel::Baseline);
/// ```
pub fn at_every_level(mut f: impl FnMut(SimdLevel)) {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _cap = LOCK
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    for level in SimdLevel::ALL.into_iter().filter(|l| l.detected()) {
        set_simd_cap(Some(level));
        assert_eq!(simd_level(), level);
        f(level);
    }
    set_simd_cap(None);
    let skipped: Vec<&str> = SimdLevel::ALL
        .into_iter()
        .filter(|l| !l.detected())
        .map(|l| l.name())
        .collect();
    if !skipped.is_empty() {
        // Past the test harness's capture: a passing run shows the skip.
        use std::io::Write as _;
        let _ = writeln!(
            std::io::stderr(),
            "note: skipped levels (this CPU lacks them): {skipped:?}"
        );
    }
}

/// Caps the instruction set of every dispatched kernel at `level` for the
/// whole process (`None`: no cap), e.g. to test or time the AVX2 or the
/// baseline kernels on an AVX-512 CPU; overrides `FMAPS_SIMD`. Kernels
/// without FMA at the baseline level may round differently (see
/// [`SimdLevel::mul_add`]); exact searches (fmaps-nearest) return the same
/// rows at every level. faer's own GEMMs dispatch on their own and are
/// not affected.
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

/// A computation compiled for every level by [`dispatch`]: its `run` must
/// be `#[inline(always)]` (so that it is compiled inside each level's
/// target-feature function) and should avoid closures in hot loops (a
/// closure is a separate function, compiled for the baseline).
pub trait Kernel {
    /// What the kernel returns.
    type Output;
    /// Runs the kernel; `level` is the level it was compiled for (a
    /// constant after inlining: branch on it freely).
    fn run(self, level: SimdLevel) -> Self::Output;
}

/// Runs `kernel` compiled for the widest level this CPU has within the cap
/// (see [`simd_level`]).
pub fn dispatch<K: Kernel>(kernel: K) -> K::Output {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma,bmi1,bmi2,popcnt,lzcnt")]
        fn v4<K: Kernel>(kernel: K) -> K::Output {
            kernel.run(SimdLevel::Avx512)
        }
        #[target_feature(enable = "avx2,fma,bmi1,bmi2,popcnt,lzcnt")]
        fn v3<K: Kernel>(kernel: K) -> K::Output {
            kernel.run(SimdLevel::Avx2)
        }
        if has_v4() {
            // SAFETY: the CPU has the features (runtime check).
            return unsafe { v4(kernel) };
        }
        if has_v3() {
            // SAFETY: as above.
            return unsafe { v3(kernel) };
        }
    }
    kernel.run(SimdLevel::Baseline)
}

/// Asks the CPU to bring the cache lines of `data` into its caches (a
/// hint, e.g. for a row about to be gathered from anywhere in a large
/// matrix: the hardware prefetcher cannot guess such an address); no
/// effect on any result, nothing on targets without a prefetch
/// instruction here.
///
/// ```
/// let row = vec![1.0f64; 150];
/// fmaps_simd::prefetch(&row);
/// assert_eq!(row.iter().sum::<f64>(), 150.0);
/// ```
#[inline(always)]
pub fn prefetch<T>(data: &[T]) {
    #[cfg(target_arch = "x86_64")]
    {
        let bytes = std::mem::size_of_val(data);
        let p = data.as_ptr().cast::<i8>();
        let mut off = 0;
        while off < bytes {
            // SAFETY: SSE is part of x86-64's baseline; a prefetch reads
            // nothing and cannot fault (the address is inside `data`).
            unsafe {
                std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p.add(off));
            }
            off += 64;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = data;
}

/// `a · b` (over the shorter length) summed in eight lanes (lane j takes
/// the terms j, j + 8, …; then a fixed tree of the lanes): a plain running
/// sum of f64 is one chain of dependent additions, eight lanes are one
/// AVX-512 register (two AVX2 ones) of them. No fused multiply-adds: the
/// same bits at every level. Inline: inside a [`Kernel`] or a
/// [`dispatched!`] function it is compiled for that level.
///
/// ```
/// let x: Vec<f64> = (0..20).map(f64::from).collect();
/// assert_eq!(fmaps_simd::dot8(&x, &x), (0..20).map(|i| f64::from(i * i)).sum::<f64>());
/// ```
#[inline(always)]
pub fn dot8(a: &[f64], b: &[f64]) -> f64 {
    let mut l = [0.0f64; 8];
    let n = a.len().min(b.len());
    let (ac, bc) = (a[..n].chunks_exact(8), b[..n].chunks_exact(8));
    let (ar, br) = (ac.remainder(), bc.remainder());
    for (x, y) in ac.zip(bc) {
        for j in 0..8 {
            l[j] += x[j] * y[j];
        }
    }
    for (j, (x, y)) in ar.iter().zip(br).enumerate() {
        l[j] += x * y;
    }
    ((l[0] + l[4]) + (l[1] + l[5])) + ((l[2] + l[6]) + (l[3] + l[7]))
}

/// A function compiled three times, for AVX-512, for AVX2 and for baseline
/// x86-64, and the widest one the CPU has run (see [`has_v4`], [`has_v3`]).
#[macro_export]
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
                if $crate::has_v4() {
                    // SAFETY: the CPU has the features (runtime check).
                    return unsafe { v4($($arg),*) };
                }
                if $crate::has_v3() {
                    // SAFETY: as above.
                    return unsafe { v3($($arg),*) };
                }
            }
            body($($arg),*)
        }
    };
}

/// AVX-512 (F, BW, VL) with AVX2 and FMA, within the cap.
#[cfg(target_arch = "x86_64")]
#[doc(hidden)]
pub fn has_v4() -> bool {
    cap() >= SimdLevel::Avx512 as u8 && detected_v4()
}

/// AVX2 with FMA, BMI and the bit-count instructions, within the cap.
#[cfg(target_arch = "x86_64")]
#[doc(hidden)]
pub fn has_v3() -> bool {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Reports the level it ran at and a dot product.
    struct Probe<'a>(&'a [f64], &'a [f64]);
    impl Kernel for Probe<'_> {
        type Output = (SimdLevel, f64);
        #[inline(always)]
        fn run(self, level: SimdLevel) -> (SimdLevel, f64) {
            let mut s = 0.0;
            for (a, b) in self.0.iter().zip(self.1) {
                s = level.mul_add(*a, *b, s);
            }
            (level, s)
        }
    }

    /// Every level the CPU has runs when capped to it (and the cap is
    /// honoured), with the same dot product of exactly representable
    /// values; the levels the CPU lacks are reported as skipped.
    #[test]
    fn dispatch_runs_the_capped_level() {
        let (x, y): (Vec<f64>, Vec<f64>) = (0..37).map(|i| (i as f64, 0.5 * i as f64)).unzip();
        let want: f64 = (0..37).map(|i| 0.5 * (i * i) as f64).sum();
        for level in SimdLevel::ALL {
            if !level.detected() {
                use std::io::Write as _;
                let _ = writeln!(
                    std::io::stderr(),
                    "note: skipped, this CPU lacks {}",
                    level.name()
                );
                continue;
            }
            set_simd_cap(Some(level));
            assert_eq!(simd_level(), level);
            assert_eq!(dispatch(Probe(&x, &y)), (level, want));
        }
        set_simd_cap(None);
        assert!(SimdLevel::Baseline.detected());
    }
}
