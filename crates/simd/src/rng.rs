//! SplitMix64 (Steele, Lea & Flood, "Fast splittable pseudorandom number
//! generators", OOPSLA 2014): the workspace's one deterministic generator,
//! for start vectors, random proposals and generated shapes. Seeded, tiny,
//! the same sequence on every platform; not for cryptography.

/// A SplitMix64 generator: the state advances by the golden-ratio
/// increment and each output is the state mixed by two xor-shift-multiply
/// rounds.
#[derive(Debug, Clone)]
pub struct SplitMix(pub u64);

impl SplitMix {
    /// The next 64 random bits.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1): the top 53 bits over 2⁵³.
    #[inline]
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in (0, 1): the top 53 bits plus ½ over 2⁵³ (never 0, so its
    /// logarithm is finite).
    #[inline]
    pub fn unit_open(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// Uniform in [−1, 1): the top 53 bits over 2⁵², minus 1.
    #[inline]
    pub fn symmetric(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    /// A standard normal draw (Box–Muller, the cosine branch, from two
    /// [`SplitMix::unit_open`] draws).
    #[inline]
    pub fn normal(&mut self) -> f64 {
        let (u, v) = (self.unit_open(), self.unit_open());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first outputs from seed 0 are the published SplitMix64 test
    /// vector (as in the reference C code by Vigna).
    #[test]
    fn reference_sequence_from_seed_zero() {
        let mut r = SplitMix(0);
        assert_eq!(r.next_u64(), 0xE220_A839_7B1D_CDAF);
        assert_eq!(r.next_u64(), 0x6E78_9E6A_A1B9_65F4);
        assert_eq!(r.next_u64(), 0x06C4_5D18_8009_454F);
    }

    #[test]
    fn ranges_and_moments() {
        let mut r = SplitMix(42);
        let n = 100_000;
        let (mut s, mut s2) = (0.0, 0.0);
        for _ in 0..n {
            let (u, o, m) = (r.unit(), r.unit_open(), r.symmetric());
            assert!((0.0..1.0).contains(&u) && o > 0.0 && o < 1.0 && (-1.0..1.0).contains(&m));
            let g = r.normal();
            s += g;
            s2 += g * g;
        }
        // Mean 0 and variance 1 within five standard errors.
        let (mean, var) = (s / n as f64, s2 / n as f64);
        assert!(mean.abs() < 5.0 / (n as f64).sqrt(), "{mean}");
        assert!((var - 1.0).abs() < 5.0 * (2.0 / n as f64).sqrt(), "{var}");
    }
}
