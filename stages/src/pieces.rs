//! Text made of many short pieces, each appended by fixed-width copies.
//!
//! A scene's `graph.txt` is some seventy lines of a few pieces each, most of them a few bytes
//! long: `(`, a name, `, left of, `, another name, `)`. `String::push_str` of each costs a
//! capacity check and a call to `memcpy`, whose dispatch on the size costs more than copying
//! ten bytes; that was a fifth of a scene graph's time (extraction and text, on 2026-12-07).
//!
//! Here a piece is copied as whole [`WINDOW`]-byte blocks, which compile to a pair of vector
//! moves without a call. Every source holds [`WINDOW`] bytes of slack after its pieces
//! ([`Fixed`] is padded to a window; [`Pieces`] ends with the slack), and [`Text`] keeps
//! [`WINDOW`] bytes of room past its end: the bytes a copy writes past its piece are
//! overwritten by the next piece, or cut off at the end. A piece longer than a window takes
//! one block per started window.
//!
//! The workspace forbids `unsafe`, so the copies are of bounds-checked slices of a constant
//! length, and the text is checked as UTF-8 once, when it becomes a `String` (every piece is a
//! whole `str`, so the check cannot fail). Neither the standard library nor the string-builder
//! crates copy this way: they copy the piece's exact length, with `memcpy`.

/// The width of every copy, in bytes: a name or a label of a graph line fits in one.
pub(crate) const WINDOW: usize = 32;

/// A piece known when the program is built, padded to a window.
#[derive(Clone, Copy)]
pub(crate) struct Fixed {
    bytes: [u8; WINDOW],
    len: usize,
    text: &'static str,
}

impl Fixed {
    /// The piece `text`, at most [`WINDOW`] bytes (longer fails the build where it is a
    /// constant).
    pub(crate) const fn new(text: &'static str) -> Self {
        let source = text.as_bytes();
        assert!(
            source.len() <= WINDOW,
            "a fixed piece is at most a window long"
        );
        let mut bytes = [0; WINDOW];
        let mut i = 0;
        while i < source.len() {
            bytes[i] = source[i];
            i += 1;
        }
        Self {
            bytes,
            len: source.len(),
            text,
        }
    }

    /// The piece as a string.
    pub(crate) const fn text(&self) -> &'static str {
        self.text
    }
}

/// Strings kept one after another, each behind the same prefix, with a window of slack after
/// the last: the pieces a text repeats (the names of a graph's objects).
pub(crate) struct Pieces {
    bytes: Vec<u8>,
    /// Where each piece (its prefix included) starts in `bytes`, and its length.
    spans: Vec<(usize, usize)>,
    /// The prefix's length.
    prefix: usize,
}

impl Pieces {
    /// `prefix` followed by each of `strings`, in order.
    pub(crate) fn new<'s>(prefix: &str, strings: impl ExactSizeIterator<Item = &'s str>) -> Self {
        let mut spans = Vec::with_capacity(strings.len());
        let mut bytes = Vec::with_capacity(strings.len() * (prefix.len() + 16) + WINDOW);
        for string in strings {
            let start = bytes.len();
            bytes.extend_from_slice(prefix.as_bytes());
            bytes.extend_from_slice(string.as_bytes());
            spans.push((start, bytes.len() - start));
        }
        bytes.resize(bytes.len() + WINDOW, 0);
        Self {
            bytes,
            spans,
            prefix: prefix.len(),
        }
    }
}

/// A text being written, with a window of room past its end.
pub(crate) struct Text {
    bytes: Vec<u8>,
    len: usize,
}

impl Text {
    /// An empty text with room for about `capacity` bytes before it grows.
    pub(crate) fn with_capacity(capacity: usize) -> Self {
        Self {
            bytes: vec![0; capacity + WINDOW],
            len: 0,
        }
    }

    /// Room for `more` bytes and a window past them.
    #[inline(always)]
    fn reserve(&mut self, more: usize) {
        let needed = self.len + more + WINDOW;
        if needed > self.bytes.len() {
            self.grow(needed);
        }
    }

    #[cold]
    fn grow(&mut self, needed: usize) {
        self.bytes.resize(needed.max(2 * self.bytes.len()), 0);
    }

    /// Appends `source[start..start + len]`, where `source` holds at least a window of bytes
    /// after it, one window at a time.
    #[inline(always)]
    fn copy(&mut self, source: &[u8], start: usize, len: usize) {
        self.reserve(len);
        let mut done = 0;
        loop {
            let (from, to) = (start + done, self.len + done);
            self.bytes[to..to + WINDOW].copy_from_slice(&source[from..from + WINDOW]);
            done += WINDOW;
            if done >= len {
                break;
            }
        }
        self.len += len;
    }

    /// Appends a fixed piece.
    #[inline(always)]
    pub(crate) fn fixed(&mut self, piece: &Fixed) {
        self.reserve(piece.len);
        self.bytes[self.len..self.len + WINDOW].copy_from_slice(&piece.bytes);
        self.len += piece.len;
    }

    /// Appends string `i` of `pieces` behind its prefix.
    #[inline(always)]
    pub(crate) fn prefixed(&mut self, pieces: &Pieces, i: usize) {
        let (start, len) = pieces.spans[i];
        self.copy(&pieces.bytes, start, len);
    }

    /// Appends string `i` of `pieces` without its prefix.
    #[inline(always)]
    pub(crate) fn bare(&mut self, pieces: &Pieces, i: usize) {
        let (start, len) = pieces.spans[i];
        self.copy(&pieces.bytes, start + pieces.prefix, len - pieces.prefix);
    }

    /// Appends any string, by its exact length.
    pub(crate) fn str(&mut self, text: &str) {
        self.reserve(text.len());
        self.bytes[self.len..self.len + text.len()].copy_from_slice(text.as_bytes());
        self.len += text.len();
    }

    /// The text.
    pub(crate) fn into_string(mut self) -> String {
        self.bytes.truncate(self.len);
        String::from_utf8(self.bytes).expect("a text of whole str pieces is UTF-8")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// What one appended: a fixed piece, a string of the pieces with or without its prefix,
    /// or any string.
    #[derive(Debug, Clone)]
    enum Step {
        Fixed(usize),
        Prefixed(usize),
        Bare(usize),
        Str(String),
    }

    const FIXED: [&str; 4] = [
        "",
        ")\n",
        ", is at, middle_right)\n",
        "0123456789abcdef0123456789abcdef",
    ];

    fn strings() -> impl Strategy<Value = Vec<String>> {
        // Empty, short, a window long and longer, and not ASCII.
        prop::collection::vec("[a-zé_ 0-9]{0,70}", 1..6)
    }

    proptest! {
        /// Any sequence of appends gives the same text as `push_str` of the same pieces, over
        /// strings of every length around the window's (0 to 70 bytes, some of two-byte
        /// characters) and a text that starts too small and grows.
        #[test]
        fn appends_as_push_str(
            strings in strings(),
            picks in prop::collection::vec((0usize..4, 0usize..64, "[a-zé]{0,40}"), 0..40),
            capacity in 0usize..64,
        ) {
            let fixed = FIXED.map(Fixed::new);
            let pieces = Pieces::new("(", strings.iter().map(String::as_str));
            let steps: Vec<Step> = picks
                .into_iter()
                .map(|(kind, i, s)| match kind {
                    0 => Step::Fixed(i % FIXED.len()),
                    1 => Step::Prefixed(i % strings.len()),
                    2 => Step::Bare(i % strings.len()),
                    _ => Step::Str(s),
                })
                .collect();
            let mut text = Text::with_capacity(capacity);
            let mut expected = String::new();
            for step in &steps {
                match step {
                    Step::Fixed(i) => {
                        text.fixed(&fixed[*i]);
                        expected.push_str(FIXED[*i]);
                    }
                    Step::Prefixed(i) => {
                        text.prefixed(&pieces, *i);
                        expected.push('(');
                        expected.push_str(&strings[*i]);
                    }
                    Step::Bare(i) => {
                        text.bare(&pieces, *i);
                        expected.push_str(&strings[*i]);
                    }
                    Step::Str(s) => {
                        text.str(s);
                        expected.push_str(s);
                    }
                }
            }
            prop_assert_eq!(text.into_string(), expected);
        }
    }

    /// Pieces longer than a window, between short ones, are copied whole, the later pieces
    /// written over the earlier ones' windows.
    #[test]
    fn long_pieces_are_copied_whole() {
        let long = "a".repeat(WINDOW) + "tail-of-a-long-name-" + &"b".repeat(WINDOW + 3);
        let pieces = Pieces::new("(", [long.as_str(), "x"].into_iter());
        let mut text = Text::with_capacity(0);
        text.prefixed(&pieces, 0);
        text.bare(&pieces, 1);
        text.bare(&pieces, 0);
        assert_eq!(text.into_string(), format!("({long}x{long}"));
    }
}
