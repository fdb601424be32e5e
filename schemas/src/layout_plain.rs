//! The quick reader of dataset layouts: a layout as mesa writes it, read straight into its type
//! in one pass of the text, without the generic [`Value`](serde_json::Value) and the JSON
//! Schema walk of [`read_layout_text`](crate::layout_file::read_layout_text).
//!
//! **Why.** Every stage after `place` reads a layout per scene, and the general reader spent
//! 41 µs on a 10 KB demo layout: most of it building a `Value` (a map and a string per key,
//! 30 µs alone) and walking the schema with JSON paths (13 µs alone), then 2.6 µs converting to
//! the type. Read straight into the type through serde's visitors, the same layout took 16 µs
//! (criterion, `schemas/benches/layout.rs`: 22 against 58.5 µs on a 12.6 KB layout).
//!
//! **Why by hand, not through serde_json.** A 16.7 KB layout of the 1,000-scene demo (13
//! objects, 250 numbers, pretty-printed) still took 37 µs through serde_json's visitors, a
//! third of `mesa graph --force`'s time a scene; most of it went to the numbers (serde_json's
//! exact `float_roundtrip` parser, after its byte-by-byte scan) and to its token machinery, and
//! serde_json hands out no number's text to parse it another way. This reader is a scanner
//! of the one shape it takes:
//! - runs of spaces are passed eight bytes at a time (a pretty layout is a third indentation);
//! - a string is scanned eight bytes at a time, the first quote, backslash or control byte
//!   found from the word's bits; one with an escape is decoded by serde_json itself;
//! - a number's digits are checked and gathered in one pass, eight at a time where they can
//!   be, and converted exactly (below).
//!
//! On that layout it takes 31 µs against serde's 37 µs (the same binary, 20,000 reads, best of
//! five, the system allocator); `docs/performance.md` has what it did to `mesa graph`.
//!
//! **Numbers are the bits serde_json gives.** serde_json (built with `float_roundtrip`, as mesa
//! builds it) rounds every decimal correctly, and so does every whole number it reads as an
//! integer and converts. Here a number of at most 19 digits whose value is at most 2^53 and
//! whose power of ten is at most 22 either way is one exact multiplication or division of two
//! exact f64s, which IEEE arithmetic rounds correctly (Clinger's fast path, the first step of
//! every exact parser); another of at most 19 digits whose power of ten is within ±27 goes to
//! Eisel–Lemire on the digits gathered ([`crate::decimal`]; a quarter of a layout's numbers,
//! whose 16 or 17 digits exceed 2^53); any other goes to Rust's own `f64` parser, which rounds
//! every input correctly. `tests::numbers_read_as_serde_json_reads_them` compares the bits
//! with serde_json's on 80,000 spellings (random doubles over the whole range, shortest and cut
//! short, plain and with exponents, the edges of each path), and fails if the fast path's
//! division is made an inexact multiplication or its bound raised to 2^54.
//!
//! **It only ever accepts what the general reader accepts, with the same result.** It declines
//! (returns `None`, and the general reader runs and reports every problem with its JSON path)
//! at anything outside the plain shape:
//! - a key it does not know, at the top or in an object (the general reader keeps those in
//!   `extra`), or a key written twice, or a key with an escape in it;
//! - a value of another type than the field's (`null` for a required field, a string for a
//!   number, an array of the wrong length), or `NaN` or `Infinity`;
//! - a `schema` other than [`LAYOUT_SCHEMA`];
//! - a string that carries the marker of a rewritten non-finite number
//!   ([`NONFINITE_PREFIX`]);
//! - what the schema bounds (a size or scale factor not above 0) or the semantic checks
//!   ([`DatasetLayout::problems`]) refuse;
//! - trailing text after the document.
//!
//! What remains is a document that the schema accepts, with no key for `extra`; its numbers
//! are serde_json's bits (above) and its strings serde_json's (copied as they are when they hold
//! no escape, which is what serde_json does with them, decoded by serde_json when they do).
//! `tests::accepts_only_what_the_general_reader_accepts` checks it against the general reader
//! on thousands of generated and mutated layouts (numbers spelled every way JSON allows and
//! some it refuses, strings with escapes and control characters among the mutations).

use crate::json::NONFINITE_PREFIX;
use crate::layout::{DatasetLayout, LayoutObject, Provenance, LAYOUT_SCHEMA};
use crate::units::{PositionCm, QuatXyzw, ScaleFactor, SizeCm, ZoneCm};

/// `text` read as a dataset layout when it has the plain shape (module docs) and is valid;
/// `None` when the general reader must decide.
pub fn read_plain_dataset_layout(text: &str) -> Option<DatasetLayout> {
    let mut scan = Scan {
        bytes: text.as_bytes(),
        text,
        at: 0,
    };
    let layout = scan.layout()?;
    scan.skip_space();
    if scan.at != scan.bytes.len() {
        return None;
    }
    (within_schema_bounds(&layout) && layout.problems().is_empty()).then_some(layout)
}

/// A reading position in the text. Every method returns `None` to decline (module docs).
struct Scan<'a> {
    bytes: &'a [u8],
    text: &'a str,
    at: usize,
}

impl<'a> Scan<'a> {
    /// Skips JSON's whitespace (space, tab, line feed, carriage return), as serde_json does.
    /// A pretty-printed layout is a third indentation: runs of spaces are passed eight bytes
    /// at a time.
    #[inline]
    fn skip_space(&mut self) {
        let bytes = self.bytes;
        let mut i = self.at;
        if !bytes.get(i).is_some_and(|&b| is_space(b)) {
            return;
        }
        loop {
            if let Some(word) = word_at(bytes, i) {
                let other = word ^ ONES.wrapping_mul(u64::from(b' '));
                if other == 0 {
                    i += 8;
                    continue;
                }
                // The spaces before the first other byte, then that byte if it is whitespace.
                i += (other.trailing_zeros() / 8) as usize;
            } else {
                while bytes.get(i) == Some(&b' ') {
                    i += 1;
                }
            }
            if !bytes.get(i).is_some_and(|&b| is_space(b)) {
                break;
            }
            i += 1;
        }
        self.at = i;
    }

    /// The next byte after whitespace, not taken.
    #[inline]
    fn peek(&mut self) -> Option<u8> {
        self.skip_space();
        self.bytes.get(self.at).copied()
    }

    /// Takes `byte`, after whitespace.
    #[inline]
    fn expect(&mut self, byte: u8) -> Option<()> {
        (self.peek()? == byte).then(|| self.at += 1)
    }

    /// Takes the literal `null` if it comes next.
    fn null(&mut self) -> Option<bool> {
        if self.peek()? != b'n' {
            return Some(false);
        }
        self.bytes[self.at..]
            .starts_with(b"null")
            .then(|| self.at += 4)
            .map(|()| true)
    }

    /// The members of an object, each key handed to `member`, which reads its value. A key
    /// with an escape declines, as the serde reader's borrowed keys did.
    fn object(&mut self, mut member: impl FnMut(&mut Self, &'a str) -> Option<()>) -> Option<()> {
        self.expect(b'{')?;
        if self.peek()? == b'}' {
            self.at += 1;
            return Some(());
        }
        loop {
            self.skip_space();
            let key = self.plain_string()?;
            self.expect(b':')?;
            member(self, key)?;
            match self.peek()? {
                b',' => self.at += 1,
                b'}' => {
                    self.at += 1;
                    return Some(());
                }
                _ => return None,
            }
        }
    }

    /// The items of an array, each read by `item`.
    fn array(&mut self, mut item: impl FnMut(&mut Self) -> Option<()>) -> Option<()> {
        self.expect(b'[')?;
        if self.peek()? == b']' {
            self.at += 1;
            return Some(());
        }
        loop {
            item(self)?;
            match self.peek()? {
                b',' => self.at += 1,
                b']' => {
                    self.at += 1;
                    return Some(());
                }
                _ => return None,
            }
        }
    }

    /// Where the string starting at the quote `self.at` ends (its closing quote), passing
    /// escapes, and whether it has any; `None` for a control character (serde_json refuses
    /// it) or a string that does not end. Eight bytes at a time: the first byte that is a
    /// quote, a backslash or below 0x20 is found from the word's bits.
    #[inline]
    fn string_end(&self) -> Option<(usize, bool)> {
        let bytes = self.bytes;
        let mut i = self.at + 1;
        let mut escaped = false;
        loop {
            let special = match word_at(bytes, i) {
                Some(word) => {
                    let found = zero_byte(word ^ ONES.wrapping_mul(u64::from(b'"')))
                        | zero_byte(word ^ ONES.wrapping_mul(u64::from(b'\\')))
                        | below_0x20(word);
                    if found == 0 {
                        i += 8;
                        continue;
                    }
                    // The lowest flagged byte is a true one (a borrow only runs upwards).
                    i + (found.trailing_zeros() / 8) as usize
                }
                None => {
                    let rest = bytes.get(i..)?;
                    i + rest
                        .iter()
                        .position(|&b| b == b'"' || b == b'\\' || b < 0x20)?
                }
            };
            match bytes[special] {
                b'"' => return Some((special, escaped)),
                b'\\' => {
                    escaped = true;
                    i = special + 2;
                }
                _ => return None,
            }
        }
    }

    /// A string without escapes, borrowed from the text (after whitespace taken by the
    /// caller); one with an escape declines.
    fn plain_string(&mut self) -> Option<&'a str> {
        if self.bytes.get(self.at) != Some(&b'"') {
            return None;
        }
        let (end, escaped) = self.string_end()?;
        if escaped {
            return None;
        }
        let start = self.at + 1;
        self.at = end + 1;
        // Both ends are ASCII quotes, so the slice falls on character boundaries.
        Some(&self.text[start..end])
    }

    /// A string value, owned: one without escapes copied, one with escapes decoded by
    /// serde_json itself (the same result as the serde reader's, by the same code).
    fn string(&mut self) -> Option<String> {
        self.skip_space();
        if self.bytes.get(self.at) != Some(&b'"') {
            return None;
        }
        let start = self.at;
        let (end, escaped) = self.string_end()?;
        self.at = end + 1;
        if escaped {
            serde_json::from_str(&self.text[start..=end]).ok()
        } else {
            Some(self.text[start + 1..end].to_owned())
        }
    }

    /// A number as JSON spells it (`-`, digits without a leading zero, an optional fraction
    /// and exponent), as an f64 rounded correctly, as serde_json (with `float_roundtrip`)
    /// rounds it; whole numbers too, which serde_json reads as integers and converts, which
    /// rounds correctly as well.
    ///
    /// The digits are gathered as they are checked. With at most 19 of them, a value of at
    /// most 2^53 and a power of ten of at most 22 either way, both are exact f64s and one
    /// multiplication or division rounds correctly (Clinger's fast path, the one every exact
    /// parser takes first); other numbers of at most 19 digits at powers within ±27 are
    /// rounded by Eisel–Lemire on the same digits ([`crate::decimal`]); any other number goes
    /// to Rust's own parser, which rounds every input correctly. What serde_json refuses or
    /// handles apart declines: a number out of range, and one so small that it rounds to zero
    /// although it has a digit other than zero.
    fn number(&mut self) -> Option<f64> {
        self.skip_space();
        let bytes = self.bytes;
        let start = self.at;
        let mut i = start;
        let negative = bytes.get(i) == Some(&b'-');
        if negative {
            i += 1;
        }
        let mut digits = Digits::default();
        match bytes.get(i)? {
            b'0' => {
                i += 1;
                digits.count += 1;
            }
            b'1'..=b'9' => {
                digits.take(bytes, &mut i);
            }
            _ => return None,
        }
        let mut exponent = 0i64;
        if bytes.get(i) == Some(&b'.') {
            i += 1;
            let fraction = digits.take(bytes, &mut i);
            if fraction == 0 {
                return None;
            }
            exponent -= i64::from(fraction);
        }
        if matches!(bytes.get(i), Some(b'e' | b'E')) {
            i += 1;
            let sign = match bytes.get(i) {
                Some(b'-') => {
                    i += 1;
                    -1
                }
                Some(b'+') => {
                    i += 1;
                    1
                }
                _ => 1,
            };
            let from = i;
            let mut value = 0i64;
            while let Some(&b) = bytes.get(i) {
                let d = b.wrapping_sub(b'0');
                if d > 9 {
                    break;
                }
                value = (value * 10 + i64::from(d)).min(1 << 40);
                i += 1;
            }
            if i == from {
                return None;
            }
            exponent += sign * value;
        }
        self.at = i;
        let Digits {
            mantissa,
            count,
            nonzero,
        } = digits;
        if count <= 19 && mantissa <= 1 << 53 && (-22..=22).contains(&exponent) {
            let power = POWERS_OF_TEN[exponent.unsigned_abs() as usize];
            let magnitude = if exponent < 0 {
                mantissa as f64 / power
            } else {
                mantissa as f64 * power
            };
            return Some(if negative { -magnitude } else { magnitude });
        }
        // At most 19 digits at the powers of a layout: Eisel–Lemire on the digits gathered.
        if count <= 19 {
            if let Some(magnitude) = crate::decimal::to_f64(mantissa, exponent) {
                return Some(if negative { -magnitude } else { magnitude });
            }
        }
        let x: f64 = self.text[start..i].parse().ok()?;
        (x.is_finite() && (x != 0.0 || !nonzero)).then_some(x)
    }

    /// `null`, or what `read` reads.
    fn optional<T>(&mut self, read: impl FnOnce(&mut Self) -> Option<T>) -> Option<Option<T>> {
        if self.null()? {
            return Some(None);
        }
        read(self).map(Some)
    }

    /// An array of any length, each item read by `item`.
    fn list<T>(&mut self, mut item: impl FnMut(&mut Self) -> Option<T>) -> Option<Vec<T>> {
        let mut list = Vec::new();
        self.array(|scan| {
            list.push(item(scan)?);
            Some(())
        })?;
        Some(list)
    }

    /// An array of exactly `N` numbers.
    fn numbers<const N: usize>(&mut self) -> Option<[f64; N]> {
        let mut out = [0.0; N];
        let mut n = 0;
        self.array(|scan| {
            let slot = out.get_mut(n)?;
            *slot = scan.number()?;
            n += 1;
            Some(())
        })?;
        (n == N).then_some(out)
    }

    /// A whole number that fits a u32, written with digits only (serde_json refuses `2.0`,
    /// `2e0` and a minus sign for an integer; a leading zero is no JSON).
    fn u32(&mut self) -> Option<u32> {
        self.skip_space();
        let bytes = self.bytes;
        let start = self.at;
        let end = start
            + bytes[start..]
                .iter()
                .position(|b| !b.is_ascii_digit())
                .unwrap_or(bytes.len() - start);
        let text = &self.text[start..end];
        if text.is_empty()
            || text.len() > 1 && text.starts_with('0')
            || matches!(bytes.get(end), Some(b'.' | b'e' | b'E'))
        {
            return None;
        }
        self.at = end;
        text.parse().ok()
    }

    fn layout(&mut self) -> Option<DatasetLayout> {
        let mut schema = None;
        let mut zone = None;
        let mut restricted = None;
        let mut objects = None;
        self.object(|scan, key| match key {
            "schema" => {
                let value = scan.string()?;
                if value != LAYOUT_SCHEMA {
                    return None;
                }
                once(&mut schema, value)
            }
            "item_placement_zone" => once(&mut zone, ZoneCm(scan.numbers()?)),
            "restricted_zone" => once(
                &mut restricted,
                scan.optional(|scan| scan.numbers().map(ZoneCm))?,
            ),
            "objects" => once(&mut objects, scan.list(Self::object_entry)?),
            _ => None,
        })?;
        Some(DatasetLayout {
            schema: schema.unwrap_or_else(|| LAYOUT_SCHEMA.to_owned()),
            zone_cm: zone?,
            restricted_zone_cm: restricted.flatten(),
            objects: objects?,
            extra: Default::default(),
        })
    }

    fn object_entry(&mut self) -> Option<LayoutObject> {
        let mut instance = None;
        let mut retrieved_uid = None;
        let mut position = None;
        let mut rotation = None;
        let mut size = None;
        let mut scale_factor = None;
        let mut category = None;
        let mut description = None;
        let mut z_rotation = None;
        let mut provenance = None;
        self.object(|scan, key| match key {
            "instance" => once(&mut instance, scan.string()?),
            "retrieved_uid" => once(&mut retrieved_uid, scan.string()?),
            "position" => once(&mut position, PositionCm(scan.numbers()?)),
            "rotation" => once(&mut rotation, QuatXyzw(scan.numbers()?)),
            "size" => once(&mut size, SizeCm(scan.numbers()?)),
            "scale_factor" => once(&mut scale_factor, ScaleFactor(scan.numbers()?)),
            "category" => once(&mut category, scan.optional(Self::string)?),
            "description" => once(&mut description, scan.optional(Self::string)?),
            "z_rotation" => once(&mut z_rotation, scan.optional(Self::number)?),
            "provenance" => once(&mut provenance, scan.optional(Self::provenance)?),
            _ => None,
        })?;
        Some(LayoutObject {
            instance: instance?,
            retrieved_uid: retrieved_uid?,
            position_cm: position?,
            rotation: rotation?,
            size_cm: size?,
            scale_factor: scale_factor?,
            category: category.flatten(),
            description: description.flatten(),
            z_rotation_deg: z_rotation.flatten(),
            provenance: provenance.flatten(),
            extra: Default::default(),
        })
    }

    /// A provenance object (not `null`: the caller took that).
    fn provenance(&mut self) -> Option<Provenance> {
        let mut stage = None;
        let mut source_instance = None;
        let mut notes = None;
        self.object(|scan, key| match key {
            "stage" => once(&mut stage, scan.string()?),
            "source_instance" => once(&mut source_instance, scan.optional(Self::u32)?),
            "notes" => once(&mut notes, scan.list(Self::string)?),
            _ => None,
        })?;
        Some(Provenance {
            stage: stage?,
            source_instance: source_instance.flatten(),
            notes: notes.unwrap_or_default(),
        })
    }
}

/// The digits of a number's mantissa, gathered as they are read: the first 19 as a whole
/// number (more would overflow it), how many there are, and whether any is not zero.
#[derive(Default)]
struct Digits {
    mantissa: u64,
    count: u32,
    nonzero: bool,
}

impl Digits {
    /// Takes the digits at `i` in `bytes`, moving `i` past them; gives how many there were.
    #[inline]
    fn take(&mut self, bytes: &[u8], i: &mut usize) -> u32 {
        let from = *i;
        // Eight digits at a time while they fit the 19 gathered.
        while self.count + 8 <= 19 {
            let Some(word) = word_at(bytes, *i).filter(|&w| eight_digits(w)) else {
                break;
            };
            let value = eight_digits_value(word);
            self.mantissa = self.mantissa * 100_000_000 + value;
            self.count += 8;
            self.nonzero |= value != 0;
            *i += 8;
        }
        while let Some(&b) = bytes.get(*i) {
            let d = b.wrapping_sub(b'0');
            if d > 9 {
                break;
            }
            if self.count < 19 {
                self.mantissa = self.mantissa * 10 + u64::from(d);
            }
            self.count += 1;
            self.nonzero |= d != 0;
            *i += 1;
        }
        (*i - from) as u32
    }
}

/// A byte with every bit set in each of eight lanes.
const ONES: u64 = u64::from_le_bytes([1; 8]);

/// The exact powers of ten an f64 holds, 10^0 to 10^22 (Clinger's fast path).
const POWERS_OF_TEN: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// JSON's whitespace.
#[inline]
fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\n' | b'\r' | b'\t')
}

/// The eight bytes at `i` as a little-endian word, when there are eight.
#[inline]
fn word_at(bytes: &[u8], i: usize) -> Option<u64> {
    let chunk: [u8; 8] = bytes.get(i..i + 8)?.try_into().ok()?;
    Some(u64::from_le_bytes(chunk))
}

/// Whether the eight bytes of `word` are all ASCII digits.
#[inline]
fn eight_digits(word: u64) -> bool {
    let high = ONES.wrapping_mul(0xF0);
    let digits = ONES.wrapping_mul(0x30);
    word & high == digits && word.wrapping_add(ONES.wrapping_mul(0x06)) & high == digits
}

/// The value of eight ASCII digits (the first byte the most significant), in three
/// multiplications: pairs, then fours, then the eight (as `fast_float` does).
#[inline]
fn eight_digits_value(word: u64) -> u64 {
    let mut v = word.wrapping_sub(ONES.wrapping_mul(0x30));
    v = v.wrapping_mul(10).wrapping_add(v >> 8);
    let mask = 0x0000_00FF_0000_00FF;
    let by_hundred = 100 + (1_000_000 << 32);
    let by_one = 1 + (10_000 << 32);
    ((v & mask)
        .wrapping_mul(by_hundred)
        .wrapping_add(((v >> 16) & mask).wrapping_mul(by_one))
        >> 32)
        & 0xFFFF_FFFF
}

/// The high bit of each byte of `word` that is zero (and maybe of bytes above the first such
/// one: the lowest flagged byte is always a true one).
#[inline]
fn zero_byte(word: u64) -> u64 {
    word.wrapping_sub(ONES) & !word & ONES.wrapping_mul(0x80)
}

/// The high bit of each byte of `word` below 0x20 (the lowest flagged byte is a true one).
#[inline]
fn below_0x20(word: u64) -> u64 {
    word.wrapping_sub(ONES.wrapping_mul(0x20)) & !word & ONES.wrapping_mul(0x80)
}

/// Sets a field read once; a second time declines (a key written twice).
fn once<T>(slot: &mut Option<T>, value: T) -> Option<()> {
    if slot.is_some() {
        return None;
    }
    *slot = Some(value);
    Some(())
}

/// The bounds of the JSON Schema that the type does not carry: sizes and scale factors above 0,
/// and no string that the lenient parser's non-finite marker could have produced (instance
/// names are left to [`DatasetLayout::problems`], whose name rule refuses the marker, and the
/// `schema` is checked as it is read).
fn within_schema_bounds(layout: &DatasetLayout) -> bool {
    let marked = |s: &str| s.starts_with(NONFINITE_PREFIX);
    layout.objects.iter().all(|o| {
        let provenance_marked = o
            .provenance
            .as_ref()
            .is_some_and(|p| marked(&p.stage) || p.notes.iter().any(|n| marked(n)));
        o.size_cm.0.iter().all(|&v| v > 0.0)
            && o.scale_factor.0.iter().all(|&v| v > 0.0)
            && !marked(&o.retrieved_uid)
            && !o.category.as_deref().is_some_and(marked)
            && !o.description.as_deref().is_some_and(marked)
            && !provenance_marked
    })
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;
    use serde_json::{json, Value};

    use super::*;
    use crate::layout_file::{read_layout_text, read_layout_text_general, AnyLayout, ReadLayout};

    /// A small generator (splitmix64): each case is one seed, so a failure names its seed.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }

        fn below(&mut self, n: usize) -> usize {
            (self.next() % n as u64) as usize
        }

        fn chance(&mut self, percent: u64) -> bool {
            self.next() % 100 < percent
        }

        /// A number as layouts hold them: full-precision decimals, whole numbers, tiny ones.
        fn number(&mut self, lo: f64, hi: f64) -> f64 {
            let unit = (self.next() >> 11) as f64 / (1u64 << 53) as f64;
            match self.below(10) {
                0 => (lo + unit * (hi - lo)).round(),
                1 => (lo + unit * (hi - lo)) * 1e-7,
                _ => lo + unit * (hi - lo),
            }
        }
    }

    /// A valid dataset layout as mesa writes it, with some optional fields left out.
    fn layout(rng: &mut Rng) -> Value {
        let count = rng.below(6);
        let objects: Vec<Value> = (0..count)
            .map(|i| {
                let yaw = rng.number(-180.0, 180.0);
                let half = yaw.to_radians() / 2.0;
                let mut object = json!({
                    "instance": format!("thing_{i}"),
                    "retrieved_uid": format!("{:032x}", rng.next()),
                    "position": [rng.number(0.0, 100.0), rng.number(0.0, 60.0), rng.number(0.0, 20.0)],
                    "rotation": [0.0, 0.0, half.sin(), half.cos()],
                    "size": [rng.number(0.5, 30.0), rng.number(0.5, 30.0), rng.number(0.5, 30.0)],
                    "scale_factor": [rng.number(0.5, 2.0), rng.number(0.5, 2.0), rng.number(0.5, 2.0)],
                });
                let map = object.as_object_mut().expect("object");
                if rng.chance(70) {
                    map.insert("category".into(), json!("thing"));
                }
                if rng.chance(70) {
                    map.insert("description".into(), json!("a \"quoted\" thing, été"));
                }
                if rng.chance(70) {
                    map.insert("z_rotation".into(), json!(yaw));
                }
                if rng.chance(60) {
                    map.insert(
                        "provenance".into(),
                        json!({"stage": "place", "source_instance": i, "notes": ["a note"]}),
                    );
                }
                object
            })
            .collect();
        let mut layout = json!({
            "item_placement_zone": [0.0, rng.number(50.0, 150.0), 0.0, rng.number(40.0, 80.0)],
            "objects": objects,
        });
        if rng.chance(80) {
            layout["schema"] = json!(LAYOUT_SCHEMA);
        }
        if rng.chance(50) {
            layout["restricted_zone"] = json!([10.0, 20.0, 10.0, 20.0]);
        }
        layout
    }

    /// Values that some field may be changed to: every type, bounds, specials.
    fn odd_value(rng: &mut Rng) -> Value {
        let values = [
            json!(null),
            json!(0),
            json!(0.0),
            json!(-1.5),
            json!(-0.0),
            json!(7),
            json!(u64::MAX),
            json!(1e308),
            json!(5e-324),
            json!("1"),
            json!(""),
            json!("\u{1}mesa:nonfinite:nan"),
            json!("bad name"),
            json!("thing_0"),
            json!("x".repeat(65)),
            json!([1.0, 2.0]),
            json!([1.0, 2.0, 3.0]),
            json!([0.0, 1.0, 1.0]),
            json!([1.0, 1.0, -2.0]),
            json!([0.0, 0.0, 0.0, 1.0]),
            json!([0.0, 0.0, 0.0, 2.0]),
            json!([30.0, 10.0, 0.0, 10.0]),
            json!({"stage": "x"}),
            json!(["place", 1, []]),
            json!({"stage": "x", "other": 1}),
            json!({"stage": "x", "source_instance": -1}),
            json!({"stage": "x", "source_instance": 4_294_967_296u64}),
            json!({"stage": "x", "source_instance": 2.0}),
            json!({}),
            json!(true),
        ];
        values[rng.below(values.len())].clone()
    }

    const OBJECT_KEYS: [&str; 11] = [
        "instance",
        "retrieved_uid",
        "position",
        "rotation",
        "size",
        "scale_factor",
        "category",
        "description",
        "z_rotation",
        "provenance",
        "unknown_key",
    ];
    const TOP_KEYS: [&str; 5] = [
        "schema",
        "item_placement_zone",
        "restricted_zone",
        "objects",
        "unknown_key",
    ];

    /// One change to the document: a key removed, added, or given an odd value.
    fn mutate(rng: &mut Rng, layout: &mut Value) {
        let objects = layout["objects"].as_array().map_or(0, Vec::len);
        let (target, keys): (&mut Value, &[&str]) = if objects > 0 && rng.chance(75) {
            (&mut layout["objects"][rng.below(objects)], &OBJECT_KEYS)
        } else {
            (layout, &TOP_KEYS)
        };
        let key = keys[rng.below(keys.len())];
        // An object already changed into something else stays as it is.
        let Some(map) = target.as_object_mut() else {
            return;
        };
        if rng.chance(25) {
            map.remove(key);
        } else if let Some(Value::Array(items)) = map.get_mut(key).filter(|_| rng.chance(50)) {
            // One element of a list of numbers made odd: its bounds and types.
            let specials = [
                json!(0.0),
                json!(-0.0),
                json!(-3.5),
                json!(5e-324),
                json!(1e308),
                json!("2"),
                json!(null),
                json!(4),
            ];
            if !items.is_empty() {
                let i = rng.below(items.len());
                items[i] = specials[rng.below(specials.len())].clone();
            }
        } else {
            map.insert(key.to_owned(), odd_value(rng));
        }
    }

    /// Changes made to the text: a key twice, a non-finite token, an escaped key, a byte-order
    /// mark, text after the document, an object written as something else.
    fn mutate_text(rng: &mut Rng, text: &str) -> String {
        // A valid value for each key, to write the key twice.
        const TWICE: [(&str, &str); 17] = [
            ("schema", "\"mesa.layout/1\""),
            ("item_placement_zone", "[0,10,0,10]"),
            ("restricted_zone", "[1,2,1,2]"),
            ("objects", "[]"),
            ("instance", "\"dup_0\""),
            ("retrieved_uid", "\"u\""),
            ("position", "[1,1,1]"),
            ("rotation", "[0,0,0,1]"),
            ("size", "[1,1,1]"),
            ("scale_factor", "[1,1,1]"),
            ("category", "\"c\""),
            ("description", "\"d\""),
            ("z_rotation", "0"),
            ("provenance", "{\"stage\":\"x\"}"),
            ("stage", "\"x\""),
            ("source_instance", "1"),
            ("notes", "[]"),
        ];
        match rng.below(11) {
            8 => number_spelled_oddly(rng, text),
            9 => {
                // A string value with an escape, a raw control character or a bad escape.
                let odd = ["\\u00e9t\\u00e9", "\\n", "\u{1}", "\\x", "\\ud800", "\\/"];
                let odd = odd[rng.below(odd.len())];
                text.replacen(": \"", &format!(": \"{odd}"), 1).replacen(
                    ":\"",
                    &format!(":\"{odd}"),
                    1,
                )
            }
            10 => text.replacen("null", ["nul", "nulll", "Null"][rng.below(3)], 1),
            0 | 1 => {
                // Among the keys the text has.
                let present: Vec<&(&str, &str)> = TWICE
                    .iter()
                    .filter(|(key, _)| text.contains(&format!("\"{key}\":")))
                    .collect();
                let Some(&&(key, value)) = present.get(rng.below(present.len().max(1))) else {
                    return text.to_owned();
                };
                let at = format!("\"{key}\":");
                text.replacen(&at, &format!("{at}{value},{at}"), 1)
            }
            2 => text.replacen(',', ",\"z_rotation\":NaN,", 1),
            3 => text.replacen("\"instance\"", "\"inst\\u0061nce\"", 1),
            4 => format!("\u{feff}{text}"),
            5 => format!("{text} x"),
            6 => format!("{text}\n  "),
            _ => text.replacen("1", "Infinity", 1),
        }
    }

    /// One number of the text spelled another way: each form JSON allows for a value, the
    /// limits of f64, and forms JSON refuses.
    fn number_spelled_oddly(rng: &mut Rng, text: &str) -> String {
        const SPELLINGS: [&str; 24] = [
            "1E2",
            "1e+2",
            "25e-1",
            "-0",
            "-0.0",
            "0e999999999999999999",
            "1e-400",
            "1e400",
            "01",
            "1.",
            ".5",
            "+1",
            "-",
            "1e",
            "12345678901234567890123",
            "9007199254740993",
            "-9223372036854775809",
            "0.30000000000000004",
            "2.2250738585072011e-308",
            "4.9e-324",
            "1.7976931348623157e308",
            "1.7976931348623159e308",
            "7.0000000000000000000000000000000000000000000001",
            "3",
        ];
        let bytes = text.as_bytes();
        let starts: Vec<usize> = (1..bytes.len())
            .filter(|&i| {
                (bytes[i].is_ascii_digit() || bytes[i] == b'-')
                    && matches!(bytes[i - 1], b' ' | b'[' | b',' | b':' | b'\n')
            })
            .collect();
        let Some(&start) = starts.get(rng.below(starts.len().max(1))) else {
            return text.to_owned();
        };
        let end = start
            + bytes[start..]
                .iter()
                .position(|b| !b"0123456789.eE+-".contains(b))
                .unwrap_or(bytes.len() - start);
        let spelling = SPELLINGS[rng.below(SPELLINGS.len())];
        format!("{}{spelling}{}", &text[..start], &text[end..])
    }

    fn canonical(read: &Result<ReadLayout, Vec<crate::Problem>>) -> String {
        match read {
            Ok(ReadLayout {
                form,
                layout: AnyLayout::Dataset(layout),
            }) => format!("{form:?} {}", serde_json::to_string(layout).expect("json")),
            other => format!("{other:?}"),
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(4000))]

        /// Whatever the quick reader accepts, the general reader accepts with the same layout
        /// (compared as JSON, so that -0.0 and 0.0 differ); and `read_layout_text` gives the
        /// general reader's result, problems included, on every document. The control: an
        /// unchanged layout is always taken by the quick reader, and a share of the changed
        /// ones is not (counted in `the_quick_reader_declines_each_change_the_schema_refuses`).
        #[test]
        fn accepts_only_what_the_general_reader_accepts(seed in any::<u64>()) {
            let mut rng = Rng(seed);
            let mut document = layout(&mut rng);
            let changes = rng.below(4);
            for _ in 0..changes {
                mutate(&mut rng, &mut document);
            }
            let mut text = if rng.chance(50) {
                serde_json::to_string_pretty(&document).expect("json")
            } else {
                serde_json::to_string(&document).expect("json")
            };
            let text_changed = rng.chance(40);
            if text_changed {
                text = mutate_text(&mut rng, &text);
            }
            let general = read_layout_text_general(&text);
            if let Some(quick) = read_plain_dataset_layout(&text) {
                let quick = Ok(ReadLayout { form: LayoutForm::Dataset, layout: AnyLayout::Dataset(quick) });
                prop_assert_eq!(canonical(&quick), canonical(&general), "{}", text);
            } else if changes == 0 && !text_changed {
                prop_assert!(false, "an unchanged layout was declined: {}", text);
            }
            prop_assert_eq!(canonical(&read_layout_text(&text)), canonical(&general));
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(3000))]

        /// Damaged text (cut anywhere, a byte changed to any value where that leaves UTF-8,
        /// or a run of bytes repeated) never makes the scanner panic or loop: it declines or
        /// reads, and what it reads the general reader reads the same. The control: the text
        /// undamaged is read.
        #[test]
        fn damaged_text_is_declined_or_read_as_the_general_reader_reads_it(
            seed in any::<u64>(),
            cut in 0.0..1.0f64,
            byte in any::<u8>(),
            damage in 0..3usize,
        ) {
            let mut rng = Rng(seed);
            let document = layout(&mut rng);
            let text = serde_json::to_string_pretty(&document).expect("json");
            prop_assert!(read_plain_dataset_layout(&text).is_some());
            let at = ((text.len() as f64 * cut) as usize).min(text.len());
            let mut bytes = text.clone().into_bytes();
            match damage {
                0 => bytes.truncate(at),
                1 if at < bytes.len() => bytes[at] = byte,
                _ => {
                    let end = (at + 1 + usize::from(byte % 16)).min(bytes.len());
                    let run = bytes[at..end].to_vec();
                    bytes.splice(at..at, run);
                }
            }
            let Ok(damaged) = String::from_utf8(bytes) else {
                return Ok(());
            };
            if let Some(quick) = read_plain_dataset_layout(&damaged) {
                let quick = Ok(ReadLayout { form: LayoutForm::Dataset, layout: AnyLayout::Dataset(quick) });
                prop_assert_eq!(canonical(&quick), canonical(&read_layout_text_general(&damaged)));
            }
        }
    }

    /// One number read by the scanner alone: its value, and where it stopped.
    fn scanned(text: &str) -> Option<(f64, usize)> {
        let mut scan = Scan {
            bytes: text.as_bytes(),
            text,
            at: 0,
        };
        scan.number().map(|x| (x, scan.at))
    }

    /// Every number the scanner reads has the bits serde_json (with `float_roundtrip`, as mesa
    /// builds it) gives the same text, on both of its paths: the fast one (at most 19 digits,
    /// a value up to 2^53, a power of ten up to 22) and Rust's parser. The spellings: random
    /// doubles over the whole range, shortest and cut to 1 to 17 digits, in plain and
    /// exponent form, whole numbers around 2^53 and 2^64, and the edges of each path. The
    /// control: serde_json's reading differs from a naive one (digits times a power of ten)
    /// on some of them, so the comparison can tell a wrong rounding.
    #[test]
    fn numbers_read_as_serde_json_reads_them() {
        let mut rng = Rng(0x5eed_f00d);
        let mut spellings: Vec<String> = [
            "0",
            "-0",
            "0.0",
            "-0.0",
            "1",
            "9007199254740992",
            "9007199254740993",
            "18446744073709551615",
            "18446744073709551616",
            "123456789012345678901234",
            "1e22",
            "1e23",
            "1E-22",
            "1e-23",
            "4.35e-5",
            "0.1",
            "0.30000000000000004",
            "5e-324",
            "2.2250738585072011e-308",
            "1.7976931348623157e308",
            "9.999999999999999e22",
            "0.000000000000000000000000000001",
            "1234567890123456789",
            "12345678901234567890",
            "7.0000000000000000000000000000000000000000000001",
            "0e999999",
            "25e-1",
            "1e+2",
        ]
        .iter()
        .map(|s| (*s).to_owned())
        .collect();
        for _ in 0..20_000 {
            let x = match rng.below(3) {
                0 => f64::from_bits(rng.next()),
                1 => rng.number(-1000.0, 1000.0),
                _ => (rng.next() >> rng.below(64)) as f64,
            };
            if !x.is_finite() {
                continue;
            }
            spellings.push(format!("{x}"));
            spellings.push(format!("{x:e}"));
            spellings.push(format!("{x:.*e}", rng.below(17)));
            spellings.push(format!("{:.*}", rng.below(20), x));
        }
        let mut naive_differs = 0;
        for text in &spellings {
            let reference = serde_json::from_str::<f64>(text).ok();
            match scanned(text) {
                Some((x, end)) => {
                    assert_eq!(end, text.len(), "{text}");
                    let reference = reference.unwrap_or_else(|| panic!("{text}: serde refuses"));
                    assert_eq!(x.to_bits(), reference.to_bits(), "{text}");
                }
                // Declined: serde refuses it too, or reads a non-finite value or zero from
                // digits that are not all zero (out of range for this reader).
                None => assert!(
                    reference.is_none_or(|r| !r.is_finite() || r == 0.0),
                    "{text} declined, serde reads {reference:?}"
                ),
            }
            if let (Some(reference), Some((mantissa, exponent))) = (reference, naive(text)) {
                naive_differs += usize::from(mantissa * 10f64.powi(exponent) != reference);
            }
        }
        assert!(naive_differs > 100, "{naive_differs}");
    }

    /// A number's digits as an f64 and its power of ten, the way a careless reader takes them.
    fn naive(text: &str) -> Option<(f64, i32)> {
        let (mantissa, exponent) = match text.split_once(['e', 'E']) {
            Some((m, e)) => (m, e.parse::<i32>().ok()?),
            None => (text, 0),
        };
        let (whole, fraction) = mantissa.split_once('.').unwrap_or((mantissa, ""));
        let digits: f64 = format!("{whole}{fraction}").parse::<i128>().ok()? as f64;
        Some((digits, exponent - fraction.len() as i32))
    }

    use crate::layout_file::LayoutForm;

    /// Each change that the general reader refuses, the quick reader declines; the control is
    /// the same document unchanged, which both accept.
    #[test]
    fn the_quick_reader_declines_each_change_the_schema_refuses() {
        let base = r#"{"schema": "mesa.layout/1", "item_placement_zone": [0, 100, 0, 50],
            "objects": [{"instance": "mug_0", "retrieved_uid": "u", "position": [1, 2, 3],
            "rotation": [0, 0, 0, 1], "size": [8, 8, 10], "scale_factor": [1, 1, 1],
            "provenance": {"stage": "place", "source_instance": 3}}]}"#;
        assert!(read_layout_text_general(base).is_ok());
        assert!(read_plain_dataset_layout(base).is_some());
        let refused = [
            ("[8, 8, 10]", "[8, 0, 10]"),
            ("[8, 8, 10]", "[8, -8, 10]"),
            ("\"scale_factor\": [1, 1, 1]", "\"scale_factor\": [1, 0, 1]"),
            ("[0, 0, 0, 1]", "[0, 0, 0, 2]"),
            ("[0, 100, 0, 50]", "[100, 0, 0, 50]"),
            ("\"mug_0\"", "\"mug 0\""),
            ("\"mug_0\"", "\"\\u0001mesa:nonfinite:nan\""),
            ("\"mesa.layout/1\"", "\"mesa.layout/2\""),
            ("[1, 2, 3]", "[1, 2]"),
            ("[1, 2, 3]", "[1, 2, \"3\"]"),
            ("\"retrieved_uid\": \"u\",", ""),
            ("\"place\"", "null"),
            ("\"source_instance\": 3", "\"source_instance\": -3"),
            (
                "{\"stage\": \"place\", \"source_instance\": 3}",
                "[\"place\", 3, []]",
            ),
            (
                "\"size\": [8, 8, 10]",
                "\"size\": [8, 8, 10], \"size\": [8, 8, 10]",
            ),
        ];
        for (from, to) in refused {
            let text = base.replacen(from, to, 1);
            assert_ne!(text, base, "{from}");
            assert!(read_layout_text_general(&text).is_err(), "{text}");
            assert!(read_plain_dataset_layout(&text).is_none(), "{text}");
        }
        // Accepted by both, but with a key for `extra`: declined, the general reader keeps it.
        let extra = base.replacen("\"objects\"", "\"other_tool\": 1, \"objects\"", 1);
        assert!(read_plain_dataset_layout(&extra).is_none());
        let kept = read_layout_text(&extra).expect("valid");
        let AnyLayout::Dataset(layout) = kept.layout else {
            panic!("a dataset layout")
        };
        assert_eq!(layout.extra.get("other_tool"), Some(&json!(1)));
    }
}
