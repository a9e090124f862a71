//! What the CPU offers this crate's kernels: the vector levels and the
//! dispatch macro of `fmaps-simd` (the workspace's one dispatch layer),
//! and the matrix tiles (AMX, detected here). A leaf: it uses no other
//! module of the crate.
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
        amx: amx_available(),
    }
}

/// Whether the AMX tiles can run here: AMX-TILE and AMX-BF16, the tile
/// palette the kernels use, the OS's tile state, and `FMAPS_NO_AMX` unset.
/// Detected once per process.
pub(crate) fn amx_available() -> bool {
    amx::available()
}

#[cfg(not(all(target_arch = "x86_64", target_os = "linux")))]
mod amx {
    pub fn available() -> bool {
        false
    }
}

#[cfg(all(target_arch = "x86_64", target_os = "linux"))]
mod amx {
    use std::arch::asm;
    use std::arch::x86_64::{__cpuid, __cpuid_count};
    use std::sync::OnceLock;

    pub fn available() -> bool {
        static ON: OnceLock<bool> = OnceLock::new();
        *ON.get_or_init(|| {
            std::env::var_os("FMAPS_NO_AMX").is_none_or(|v| v.is_empty() || v == "0") && detect()
        })
    }

    /// CPUID: AMX-TILE and AMX-BF16, palette 1 with 8 tiles of 16 rows of
    /// 64 bytes, AVX-512F for the scans; XCR0 with the tile state; and
    /// Linux's permission for it.
    fn detect() -> bool {
        let leaf0 = __cpuid(0);
        if leaf0.eax < 0x1d {
            return false;
        }
        let (l1, l7) = (__cpuid(1), __cpuid_count(7, 0));
        let amx_bf16 = l7.edx & (1 << 22) != 0;
        let amx_tile = l7.edx & (1 << 24) != 0;
        let osxsave = l1.ecx & (1 << 27) != 0;
        if !(amx_bf16 && amx_tile && osxsave && std::arch::is_x86_feature_detected!("avx512f")) {
            return false;
        }
        // Leaf 0x1d exists (checked above).
        let palette = __cpuid_count(0x1d, 1);
        let bytes_per_row = palette.ebx & 0xffff;
        let max_names = palette.ebx >> 16;
        let max_rows = palette.ecx & 0xffff;
        if bytes_per_row < 64 || max_names < 8 || max_rows < 16 {
            return false;
        }
        let (lo, _hi): (u32, u32);
        // SAFETY: OSXSAVE is set, so XGETBV is enabled.
        unsafe {
            asm!("xgetbv", in("ecx") 0u32, out("eax") lo, out("edx") _hi, options(nomem, nostack));
        }
        if lo & (0b11 << 17) != 0b11 << 17 {
            return false;
        }
        // arch_prctl(ARCH_REQ_XCOMP_PERM, XFEATURE_XTILEDATA).
        let ret: i64;
        // SAFETY: the raw syscall only changes this process's permission;
        // the kernel clobbers rcx and r11.
        unsafe {
            asm!(
                "syscall",
                inlateout("rax") 158i64 => ret,
                in("rdi") 0x1023i64,
                in("rsi") 18i64,
                lateout("rcx") _,
                lateout("r11") _,
                options(nostack)
            );
        }
        ret == 0
    }
}
