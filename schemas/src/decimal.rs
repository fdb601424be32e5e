//! A decimal number whose digits are already gathered (a whole number `w` of at most 19
//! digits, and a power of ten `q`) rounded correctly to the nearest f64, by the Eisel–Lemire
//! algorithm (D. Lemire, "Number Parsing at a Gigabyte per Second", 2021; the algorithm of
//! Rust's own `f64` parser, `core::num::dec2flt::lemire`).
//!
//! **Why by hand.** The layout scanner ([`crate::layout_plain`]) gathers a number's digits as
//! it checks them. A number of at most 19 digits whose value is at most 2^53 and whose power
//! of ten is at most 22 is one exact division or multiplication (Clinger's fast path), but a
//! layout's coordinates mostly have 16 or 17 digits, and a quarter of them are above 2^53: for
//! those the scanner handed the text to Rust's parser, which scans the digits a second time
//! and checks the syntax again. Neither Rust's parser nor the crates of the field
//! (`fast-float2`, `lexical`) take digits already gathered, so the one step that turns them
//! into an f64 is written here, for the powers of ten of a layout, 10^-27 to 10^27. Every
//! other number still goes to Rust's parser.
//!
//! **The table.** Each power of five is kept as its 128 leading bits, made at compile time
//! ([`POWERS_OF_FIVE`]): 5^q itself for q ≥ 0 (it fits 64 bits up to 5^27, so the 128 bits are
//! exact), and ⌊2^b / 5^-q⌋ + 1 for q < 0, with b the bit length of 5^-q plus 127, as Lemire's
//! table holds them. Within those powers the algorithm never meets the case it cannot decide
//! (its "safe exponents" are -27 to 55), nor a subnormal or infinite result.
//!
//! `tests::agrees_with_rusts_parser` compares the bits with Rust's parser on a million random
//! digit strings and powers and on the ties (decimals exactly halfway between two doubles);
//! `tests::a_damaged_table_is_seen` shows that the comparison fails with a table made without
//! Lemire's + 1 or with one entry damaged.

/// The smallest and largest power of ten read here.
pub(crate) const POWERS: std::ops::RangeInclusive<i64> = -27..=27;

/// 5^q for q in [`POWERS`], as its 128 leading bits: (high 64, low 64).
const POWERS_OF_FIVE: [(u64, u64); 55] = powers_of_five();

const fn powers_of_five() -> [(u64, u64); 55] {
    let mut table = [(0u64, 0u64); 55];
    let mut i = 0;
    while i < 55 {
        let q = i as i64 - 27;
        let mut p: u64 = 1;
        let mut k = 0;
        while k < q.unsigned_abs() {
            p *= 5;
            k += 1;
        }
        let bits: u128 = if q >= 0 {
            // The most significant bit moved to the top: exact.
            (p as u128) << (p as u128).leading_zeros()
        } else {
            // ⌊2^b / p⌋ + 1, b = bit length of p + 127, by long division of the three 64-bit
            // limbs of 2^b (p < 2^63, so the quotient is below 2^128).
            let b = (64 - p.leading_zeros()) + 127;
            let limbs: [u64; 3] = [1u64 << (b - 128), 0, 0];
            let mut rem: u128 = 0;
            let mut quotient: u128 = 0;
            let mut j = 0;
            while j < 3 {
                let cur = (rem << 64) | limbs[j] as u128;
                quotient = (quotient << 64) | (cur / p as u128);
                rem = cur % p as u128;
                j += 1;
            }
            quotient + 1
        };
        table[i] = ((bits >> 64) as u64, bits as u64);
        i += 1;
    }
    table
}

/// w · 10^q rounded to the nearest f64 (ties to even), for `w` > 0 of at most 19 decimal
/// digits (exact in a u64) and `q` in [`POWERS`]; `None` outside them.
pub(crate) fn to_f64(w: u64, q: i64) -> Option<f64> {
    to_f64_with(&POWERS_OF_FIVE, w, q)
}

/// [`to_f64`] with a table of powers of five given (the tests give a damaged one).
#[inline]
fn to_f64_with(powers_of_five: &[(u64, u64); 55], w: u64, q: i64) -> Option<f64> {
    // f64: 52 explicit mantissa bits; the bias; the powers of ten where a product can fall
    // exactly halfway between two doubles (Lemire's round-to-even range).
    const SIG_BITS: i32 = 52;
    const MINIMUM_EXPONENT: i32 = -1023;
    const ROUND_TO_EVEN: std::ops::RangeInclusive<i64> = -4..=23;
    if w == 0 || w >= 10_000_000_000_000_000_000 || !POWERS.contains(&q) {
        return None;
    }
    let lz = w.leading_zeros();
    let w = w << lz;
    // The product's leading 128 bits, the low half only when the high half's bits below the
    // 55 that are kept are all ones (where the low half can carry into them).
    let (hi5, lo5) = powers_of_five[(q - POWERS.start()) as usize];
    let first = u128::from(w) * u128::from(hi5);
    let (mut lo, mut hi) = (first as u64, (first >> 64) as u64);
    let mask = u64::MAX >> (SIG_BITS + 3);
    if hi & mask == mask {
        let second_hi = ((u128::from(w) * u128::from(lo5)) >> 64) as u64;
        lo = lo.wrapping_add(second_hi);
        if second_hi > lo {
            hi += 1;
        }
    }
    let upperbit = (hi >> 63) as i32;
    let shift = upperbit + 64 - SIG_BITS - 3;
    let mut mantissa = hi >> shift;
    // ⌊log2(10^q)⌋ + 63, by the fixed-point multiplier of Lemire's paper.
    let power = ((q as i32).wrapping_mul(152_170 + 65_536) >> 16) + 63;
    let mut power2 = power + upperbit - lz as i32 - MINIMUM_EXPONENT;
    if power2 <= 0 {
        // A subnormal: not within these powers, but never guessed at.
        return None;
    }
    // Exactly halfway between two doubles: round to even.
    if lo <= 1 && ROUND_TO_EVEN.contains(&q) && mantissa & 3 == 1 && (mantissa << shift) == hi {
        mantissa &= !1;
    }
    mantissa += mantissa & 1;
    mantissa >>= 1;
    if mantissa >= 2 << SIG_BITS {
        mantissa = 1 << SIG_BITS;
        power2 += 1;
    }
    mantissa &= !(1 << SIG_BITS);
    if power2 >= 0x7FF {
        return None;
    }
    Some(f64::from_bits(mantissa | (power2 as u64) << SIG_BITS))
}

#[cfg(test)]
mod tests {
    use proptest::prelude::Rng;
    use proptest::test_runner::{RngAlgorithm, TestRng};

    use super::*;

    /// A generator with a fixed seed (proptest's), so that the cases are the same each run.
    fn rng() -> TestRng {
        TestRng::deterministic_rng(RngAlgorithm::ChaCha)
    }

    fn reference(w: u64, q: i64) -> f64 {
        format!("{w}e{q}").parse().expect("a decimal")
    }

    /// Random and chosen cases: a million random digit strings of 1 to 19 digits at every
    /// power; the ties (decimals exactly halfway between two doubles, which must round to
    /// even) and their neighbours; the largest and smallest 19-digit numbers at every power.
    fn cases() -> Vec<(u64, i64)> {
        let mut rng = rng();
        let mut cases: Vec<(u64, i64)> = Vec::new();
        for _ in 0..1_000_000 {
            let digits = 1 + rng.next_u64() % 19;
            let w = (rng.next_u64() % 10u64.pow(digits as u32)).max(1);
            let q = (rng.next_u64() % 55) as i64 - 27;
            cases.push((w, q));
        }
        for q in POWERS {
            for w in [
                1,
                9,
                (1 << 53) - 1,
                1 << 53,
                (1 << 53) + 1,
                (1 << 54) + 1,
                9_999_999_999_999_999_999,
                1_000_000_000_000_000_000,
                7_140_520_215_034_485,
                9_993_690_986_614_472,
            ] {
                cases.push((w, q));
            }
        }
        cases.extend(
            ties()
                .into_iter()
                .flat_map(|(w, q)| [(w, q), (w - 1, q), (w + 1, q)]),
        );
        cases
    }

    /// Decimals exactly halfway between two doubles, which must round to even: a 54-bit odd
    /// number o times a power of two is one. w·10^q = o·2^q when w·5^q = o (q ≥ 0), and
    /// o/2^-q when w = o·5^-q (q < 0, only down to -4 within 19 digits).
    fn ties() -> Vec<(u64, i64)> {
        let is_tie = |o: u64| o >> 53 == 1 && o % 2 == 1;
        let mut ties = Vec::new();
        for q in 0..=22i64 {
            let five = 5u64.pow(q as u32);
            let first = ((1u64 << 53) / five + 1) | 1;
            for m in (first..).step_by(2).take(100) {
                if is_tie(m * five) {
                    ties.push((m, q));
                }
            }
        }
        for q in -4..=-1i64 {
            let five = 5u64.pow(q.unsigned_abs() as u32);
            for o in ((1u64 << 53) + 1..).step_by(2).take(100) {
                assert!(is_tie(o));
                ties.push((o * five, q));
            }
        }
        ties
    }

    /// The same bits as Rust's parser on every case, the ties (rounded to even) among them.
    #[test]
    fn agrees_with_rusts_parser() {
        let cases = cases();
        assert!(ties().len() > 1000, "{}", ties().len());
        for (w, q) in cases {
            let expected = reference(w, q);
            assert_eq!(
                to_f64(w, q).map(f64::to_bits),
                Some(expected.to_bits()),
                "{w}e{q}"
            );
        }
    }

    /// Outside what it reads it declines: no digits, 20 digits, powers past the table.
    #[test]
    fn declines_what_it_does_not_read() {
        assert_eq!(to_f64(0, 0), None);
        assert_eq!(to_f64(10_000_000_000_000_000_000, 0), None);
        assert_eq!(to_f64(1, 28), None);
        assert_eq!(to_f64(1, -28), None);
        assert!(to_f64(1, 27).is_some() && to_f64(1, -27).is_some());
    }

    /// Controls: a table whose entries for negative powers lack Lemire's + 1, and one with a
    /// power's entry moved up one bit, each give other bits than Rust's parser on some of
    /// the cases.
    #[test]
    fn a_damaged_table_is_seen() {
        let cases = cases();
        let disagreements = |table: &[(u64, u64); 55]| {
            cases
                .iter()
                .filter(|&&(w, q)| {
                    to_f64_with(table, w, q).map(f64::to_bits) != Some(reference(w, q).to_bits())
                })
                .count()
        };
        let mut no_plus_one = POWERS_OF_FIVE;
        for entry in &mut no_plus_one[..27] {
            let bits = (u128::from(entry.0) << 64 | u128::from(entry.1)) - 1;
            *entry = ((bits >> 64) as u64, bits as u64);
        }
        assert!(disagreements(&no_plus_one) > 0);
        let mut shifted = POWERS_OF_FIVE;
        shifted[30].1 ^= 1 << 40;
        shifted[30].0 ^= 1 << 10;
        assert!(disagreements(&shifted) > 0);
        assert_eq!(disagreements(&POWERS_OF_FIVE), 0);
    }
}
