//! Text made of many short pieces, each appended by fixed-width copies.
//!
//! A scene's `graph.txt` is some seventy lines of a few pieces each, most of them a few bytes
//! long: `(`, a name, `, left of, `, another name, `)`. `String::push_str` of each costs a
//! capacity check and a call to `memcpy`, whose dispatch on the size costs more than copying
//! ten bytes; that was a fifth of a scene graph's time (extraction and text, on 2026-12-07).
//!
//! Here a piece is copied as whole [`WINDOW`]-byte blocks, which compile to a pair of vector
//! moves without a call, and the text moves on by the piece's length: the bytes a copy writes
//! past its piece are overwritten by the next piece, or cut off at the end. A piece comes
//! from one of two places, each with a window of bytes readable past it:
//! - a [`Fixed`] piece, known when the program is built, is padded to a window;
//! - a piece the text already holds (a name, written once in full, then repeated by
//!   [`Text::repeat`]) is read from the text itself, which keeps a window of room past its
//!   end. The copy goes forward, one window after another, to the end of the text: what it
//!   writes never reaches the part of the piece still to be read.
//!
//! A piece longer than a window takes one block per started window. The workspace forbids
//! `unsafe`, so the copies are of bounds-checked slices of a constant length, and the text is
//! checked as UTF-8 once, when it becomes a `String` (every piece is a whole `str`, so the
//! check cannot fail). Neither the standard library nor the string-builder crates copy this
//! way: they copy a piece's exact length, with `memcpy`.

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

/// Where a piece of a [`Text`] lies in it: its start and its length in bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Span {
    start: usize,
    len: usize,
}

impl Span {
    /// The span without its first `bytes` bytes (at most its length), which must end a
    /// character.
    pub(crate) fn skip(self, bytes: usize) -> Self {
        let bytes = bytes.min(self.len);
        Self {
            start: self.start + bytes,
            len: self.len - bytes,
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

    /// Appends a fixed piece.
    #[inline(always)]
    pub(crate) fn fixed(&mut self, piece: &Fixed) {
        self.reserve(piece.len);
        self.bytes[self.len..self.len + WINDOW].copy_from_slice(&piece.bytes);
        self.len += piece.len;
    }

    /// Where the text ends now: the start of a span [`Self::since`] returns.
    pub(crate) fn mark(&self) -> usize {
        self.len
    }

    /// The span from `mark` (of [`Self::mark`], on a character boundary) to the end.
    pub(crate) fn since(&self, mark: usize) -> Span {
        let start = mark.min(self.len);
        Span {
            start,
            len: self.len - start,
        }
    }

    /// Appends any string, by its exact length; returns where it lies, for [`Self::repeat`].
    pub(crate) fn str(&mut self, text: &str) -> Span {
        self.reserve(text.len());
        let start = self.len;
        self.bytes[start..start + text.len()].copy_from_slice(text.as_bytes());
        self.len += text.len();
        Span {
            start,
            len: text.len(),
        }
    }

    /// Appends again a piece the text holds (a span [`Self::str`] returned, or part of one
    /// that starts and ends on characters), one window at a time.
    #[inline(always)]
    pub(crate) fn repeat(&mut self, span: Span) {
        let Span { start, len } = span;
        assert!(start + len <= self.len, "a span of the text so far");
        self.reserve(len);
        // Every window read lies before the text's end plus a window: inside `bytes`.
        let mut done = 0;
        loop {
            let from = start + done;
            self.bytes.copy_within(from..from + WINDOW, self.len + done);
            done += WINDOW;
            if done >= len {
                break;
            }
        }
        self.len += len;
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

    const FIXED: [&str; 4] = [
        "",
        ")\n",
        ", is at, middle_right)\n",
        "0123456789abcdef0123456789abcdef",
    ];

    proptest! {
        /// Any sequence of appends gives the same text as `push_str` of the same pieces: fixed
        /// pieces, strings of every length around the window's (0 to 70 bytes, some of
        /// two-byte characters), and repeats of any earlier string, whole or without its
        /// first character, into a text that starts too small and grows.
        #[test]
        fn appends_as_push_str(
            steps in prop::collection::vec((0usize..4, 0usize..64, "[a-zé_ 0-9]{0,70}"), 0..40),
            capacity in 0usize..64,
        ) {
            let fixed = FIXED.map(Fixed::new);
            let mut text = Text::with_capacity(capacity);
            let mut expected = String::new();
            let mut written: Vec<(Span, String)> = Vec::new();
            for (kind, i, s) in steps {
                match kind {
                    0 => {
                        text.fixed(&fixed[i % FIXED.len()]);
                        expected.push_str(FIXED[i % FIXED.len()]);
                    }
                    1 | 2 if !written.is_empty() => {
                        let (span, s) = &written[i % written.len()];
                        if kind == 1 {
                            text.repeat(*span);
                            expected.push_str(s);
                        } else {
                            let first = s.chars().next().map_or(0, char::len_utf8);
                            text.repeat(span.skip(first));
                            expected.push_str(&s[first..]);
                        }
                    }
                    _ if i % 2 == 0 => {
                        written.push((text.str(&s), s.clone()));
                        expected.push_str(&s);
                    }
                    _ => {
                        // A fixed piece and a string, marked as one span.
                        let mark = text.mark();
                        text.fixed(&fixed[2]);
                        text.str(&s);
                        written.push((text.since(mark), format!("{}{s}", FIXED[2])));
                        expected.push_str(FIXED[2]);
                        expected.push_str(&s);
                    }
                }
            }
            prop_assert_eq!(text.into_string(), expected);
        }
    }

    /// A piece longer than a window, repeated right behind itself and again later, is
    /// copied whole: the copy's own writes never reach the part still to be read.
    #[test]
    fn long_pieces_repeat_whole() {
        let long = "a".repeat(WINDOW) + "tail-of-a-long-name-" + &"b".repeat(WINDOW + 3);
        let mut text = Text::with_capacity(0);
        let span = text.str(&long);
        text.repeat(span);
        text.fixed(&Fixed::new(")"));
        text.repeat(span.skip(1));
        assert_eq!(text.into_string(), format!("{long}{long}){}", &long[1..]));
    }

    /// A span that is not of the text so far is refused, not read past the text.
    #[test]
    #[should_panic(expected = "a span of the text so far")]
    fn a_span_past_the_text_is_refused() {
        let mut text = Text::with_capacity(0);
        let span = text.str("name");
        let mut other = Text::with_capacity(0);
        other.repeat(span);
    }
}
