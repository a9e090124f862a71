//! The ZoomOut schedule syntax `START:FINAL:STEP` under arbitrary input
//! (the multi-start list `K1,K2,..|none` is fuzzed with the command line).
//! Never a panic; accepted exactly when the grammar says; printing and
//! parsing again gives the same value. (The file parsers are fuzzed in
//! `fmaps-mesh-io`'s `proptest` test; `cargo xtask fuzz` runs both with
//! 10,000 cases each, `FMAPS_FUZZ_CASES`.)

use fmaps::refine::ZoomOut;
use proptest::prelude::*;

fn cases() -> u32 {
    std::env::var("FMAPS_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(256)
}

/// The grammar, independently: three unsigned integers `a:b:c` (spaces
/// around each allowed) with `0 < a <= b` and `c >= 1`.
fn schedule_spec(text: &str) -> Option<(usize, usize, usize)> {
    let parts: Vec<&str> = text.split(':').collect();
    if parts.len() != 3 {
        return None;
    }
    let mut v = [0usize; 3];
    for (slot, p) in v.iter_mut().zip(&parts) {
        let p = p.trim();
        if p.is_empty() || !p.bytes().all(|b| b.is_ascii_digit() || b == b'+') {
            return None;
        }
        *slot = p.parse().ok()?;
    }
    (v[0] > 0 && v[0] <= v[1] && v[2] > 0).then_some((v[0], v[1], v[2]))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    #[test]
    fn schedules_parse_exactly_the_grammar(text in "[0-9: +\\-a]{0,30}|[0-9]{1,25}:[0-9]{1,25}:[0-9]{1,25}") {
        let parsed = ZoomOut::with_schedule(&text).ok().map(|z| (z.k_start, z.k_final, z.step));
        prop_assert_eq!(parsed, schedule_spec(&text), "{:?}", text);
    }

    #[test]
    fn schedules_round_trip(a in 1usize..10_000, len in 0usize..10_000, c in 1usize..100_000) {
        let b = a + len;
        let z = ZoomOut::with_schedule(&format!("{a}:{b}:{c}")).unwrap();
        prop_assert_eq!((z.k_start, z.k_final, z.step), (a, b, c));
        // The sizes C takes: a + c, a + 2c, ..., the last clamped to FINAL.
        let s = z.schedule();
        prop_assert_eq!(s.len(), len.div_ceil(c));
        for (i, &k) in s.iter().enumerate() {
            prop_assert_eq!(k, (a + (i + 1) * c).min(b));
        }
        prop_assert_eq!(s.last().copied().unwrap_or(a), b);
    }

    /// START + STEP beyond usize::MAX saturates instead of overflowing.
    #[test]
    fn schedules_with_huge_steps_end_at_final(a in 1usize..1000, step in (usize::MAX / 2)..=usize::MAX) {
        let z = ZoomOut::with_schedule(&format!("{a}:{}:{step}", a + 7)).unwrap();
        prop_assert_eq!(z.schedule(), vec![a + 7]);
    }

}
