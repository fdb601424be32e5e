//! `graph/graph.json` written straight from its parts: the bytes of
//! [`crate::json::to_sorted_pretty`] on the [`GraphArtifact`] (sorted keys, two-space
//! indentation, a trailing newline), without going through serde.
//!
//! The graph stage writes one of these per scene, and serde's path cost more than extracting
//! the graph: about 25 µs of a 13 KB graph (32 edges) against 5 µs for the extraction, most of
//! it serde_json's per-token machinery (its own compact writer takes 14 µs on the same value).
//! The layout is fixed, so the keys are written in their sorted order by hand, and every piece
//! of layout between two values (comma, newline, indentation, key) is one constant; a number
//! is spelled by `zmij`, as serde_json spells it (the digits 0 to 9 and a number spelled just
//! before are written without it: 13.2 → 8.3 µs a 15 KB graph, `docs/performance.md`), and a
//! string that needs escaping goes through serde_json's writer (one that does not is copied
//! between quotes, as serde_json copies it).
//!
//! [`write_graph_json`] takes the parts borrowed ([`NodeRef`], [`EdgeRef`], [`SpacingRef`]),
//! so that the stage writes a scene graph without first building the owned artifact (a string
//! per name and a map per edge's numbers: 7 µs a scene, more than the writing itself);
//! [`GraphArtifact::to_pretty_json`] lends its own parts to the same writer. The test below
//! checks the bytes against [`crate::json::to_sorted_pretty`] on random artifacts (names that
//! need escaping, non-finite numbers, empty lists).

use crate::artifacts::GraphArtifact;

/// A node of `graph.json`, borrowed (the fields of [`crate::artifacts::GraphNode`]).
#[derive(Debug, Clone, Copy)]
pub struct NodeRef<'a> {
    /// The instance.
    pub instance: &'a str,
    /// Nine-grid cell, like `front_left` or `center`.
    pub is_at: &'a str,
    /// One of eight directions, like `front_right`.
    pub face_to: &'a str,
    /// Whether the object counted as a container.
    pub container: bool,
}

/// An edge of `graph.json`, borrowed; `numbers` yields each number with its key, **in byte
/// order of the keys** (as the artifact's map holds them).
#[derive(Debug, Clone)]
pub struct EdgeRef<'a, N> {
    /// Subject instance.
    pub subject: &'a str,
    /// The relation's label.
    pub relation: &'a str,
    /// Object instance.
    pub object: &'a str,
    /// The numbers that decided the edge, by key in byte order.
    pub numbers: N,
}

/// An `equally_spaced` entry of `graph.json`, borrowed; `numbers` as in [`EdgeRef`].
#[derive(Debug, Clone)]
pub struct SpacingRef<'a, N> {
    /// The instances by increasing coordinate.
    pub instances: [&'a str; 3],
    /// `x` or `y`.
    pub axis: &'a str,
    /// The gaps and spread, by key in byte order.
    pub numbers: N,
}

/// The bytes of `graph/graph.json` (exactly those of [`crate::json::to_sorted_pretty`] on the
/// [`GraphArtifact`] with these parts; `equally_spaced` left out when empty, as the artifact
/// skips it).
pub fn write_graph_json<'a, 'k, EN, SN>(
    schema: &str,
    scene_id: &str,
    layout: &str,
    nodes: impl ExactSizeIterator<Item = NodeRef<'a>>,
    edges: impl ExactSizeIterator<Item = EdgeRef<'a, EN>>,
    equally_spaced: impl ExactSizeIterator<Item = SpacingRef<'a, SN>>,
) -> Vec<u8>
where
    EN: IntoIterator<Item = (&'k str, f64)>,
    SN: IntoIterator<Item = (&'k str, f64)>,
{
    let mut w = Pretty {
        out: Vec::with_capacity(1024 + 480 * edges.len() + 160 * nodes.len()),
        // No number has the bits of a NaN that `f64` arithmetic does not make.
        spelled: [(u64::MAX, 0, 0); 2],
    };
    // Keys in byte order: edges, equally_spaced, layout, nodes, scene_id, schema. Every
    // member sits at a fixed depth, so each piece of layout between two values is one
    // constant (a newline, the indentation, a key), copied without a length to compute.
    w.raw(b"{\n  \"edges\": [");
    w.items(edges, |w, e| {
        w.raw(b"{\n      \"numbers\": {");
        w.numbers(e.numbers);
        w.raw(b",\n      \"object\": ");
        w.string(e.object);
        w.raw(b",\n      \"relation\": ");
        w.string(e.relation);
        w.raw(b",\n      \"subject\": ");
        w.string(e.subject);
        w.raw(b"\n    }");
    });
    if equally_spaced.len() > 0 {
        w.raw(b",\n  \"equally_spaced\": [");
        w.items(equally_spaced, |w, s| {
            w.raw(b"{\n      \"axis\": ");
            w.string(s.axis);
            w.raw(b",\n      \"instances\": [\n        ");
            w.string(s.instances[0]);
            w.raw(b",\n        ");
            w.string(s.instances[1]);
            w.raw(b",\n        ");
            w.string(s.instances[2]);
            w.raw(b"\n      ],\n      \"numbers\": {");
            w.numbers(s.numbers);
            w.raw(b"\n    }");
        });
    }
    w.raw(b",\n  \"layout\": ");
    w.string(layout);
    w.raw(b",\n  \"nodes\": [");
    w.items(nodes, |w, n| {
        w.raw(if n.container {
            b"{\n      \"container\": true,\n      \"face_to\": "
        } else {
            b"{\n      \"container\": false,\n      \"face_to\": "
        });
        w.string(n.face_to);
        w.raw(b",\n      \"instance\": ");
        w.string(n.instance);
        w.raw(b",\n      \"is_at\": ");
        w.string(n.is_at);
        w.raw(b"\n    }");
    });
    w.raw(b",\n  \"scene_id\": ");
    w.string(scene_id);
    w.raw(b",\n  \"schema\": ");
    w.string(schema);
    w.raw(b"\n}\n");
    w.out
}

impl GraphArtifact {
    /// The artifact as `graph/graph.json` holds it: exactly the bytes of
    /// [`crate::json::to_sorted_pretty`].
    pub fn to_pretty_json(&self) -> Vec<u8> {
        write_graph_json(
            &self.schema,
            &self.scene_id,
            &self.layout,
            self.nodes.iter().map(|n| NodeRef {
                instance: &n.instance,
                is_at: &n.is_at,
                face_to: &n.face_to,
                container: n.container,
            }),
            self.edges.iter().map(|e| EdgeRef {
                subject: &e.subject,
                relation: &e.relation,
                object: &e.object,
                numbers: e.numbers.iter().map(|(key, &x)| (key.as_str(), x)),
            }),
            self.equally_spaced.iter().map(|s| SpacingRef {
                instances: [&s.instances[0], &s.instances[1], &s.instances[2]],
                axis: &s.axis,
                numbers: s.numbers.iter().map(|(key, &x)| (key.as_str(), x)),
            }),
        )
    }
}

/// serde_json's pretty layout, by hand, for the one shape of `graph.json`.
struct Pretty {
    out: Vec<u8>,
    /// Where the last numbers spelled by `zmij` were written in `out`: their bits, start and
    /// length. A graph repeats some (every proximity edge of a scene has the same
    /// `max_distance_cm`), and copying an earlier spelling costs a fifth of making it.
    spelled: [(u64, usize, usize); 2],
}

impl Pretty {
    /// Bytes of the layout (a constant at every call, so the copy has a known length).
    #[inline(always)]
    fn raw(&mut self, bytes: &[u8]) {
        self.out.extend_from_slice(bytes);
    }

    /// The items of a top-level array (its `[` written), each an object at depth 2 written by
    /// `item` from its `{` to its `}`; then the `]`.
    #[inline(always)]
    fn items<T>(&mut self, items: impl ExactSizeIterator<Item = T>, item: impl Fn(&mut Self, T)) {
        if items.len() == 0 {
            self.out.push(b']');
            return;
        }
        for (i, value) in items.enumerate() {
            if i > 0 {
                self.out.push(b',');
            }
            self.raw(b"\n    ");
            item(self, value);
        }
        self.raw(b"\n  ]");
    }

    /// The members of a map of numbers at depth 3 (its `{` written), given in key order; then
    /// the `}`.
    #[inline(always)]
    fn numbers<'k>(&mut self, numbers: impl IntoIterator<Item = (&'k str, f64)>) {
        let mut any = false;
        for (key, x) in numbers {
            if any {
                self.out.push(b',');
            }
            self.raw(b"\n        ");
            self.string(key);
            self.raw(b": ");
            self.number(x);
            any = true;
        }
        if any {
            self.raw(b"\n      }");
        } else {
            self.out.push(b'}');
        }
    }

    #[inline(always)]
    fn string(&mut self, text: &str) {
        // What JSON escapes: quotes, backslashes and control characters. Names and labels
        // rarely hold any; those that do go through serde_json's writer.
        if needs_escape(text.as_bytes()) {
            // Writing to a Vec cannot fail, and a str always serialises.
            serde_json::to_writer(&mut self.out, text).expect("a string serialises");
        } else {
            self.out.reserve(text.len() + 2);
            self.out.push(b'"');
            self.out.extend_from_slice(text.as_bytes());
            self.out.push(b'"');
        }
    }

    fn number(&mut self, x: f64) {
        if !x.is_finite() {
            // As a serde_json `Value` holds it.
            self.out.extend_from_slice(b"null");
            return;
        }
        // The whole numbers 0 to 9 (ranks), as zmij spells them: the digit and `.0`.
        if x.to_bits() <= 9f64.to_bits() && f64::from(x as u8) == x {
            self.out.extend_from_slice(&[b'0' + x as u8, b'.', b'0']);
            return;
        }
        let bits = x.to_bits();
        if let Some(&(_, start, len)) = self.spelled.iter().find(|s| s.0 == bits) {
            self.out.extend_from_within(start..start + len);
            return;
        }
        // serde_json's own spelling of an f64 (its `write_f64`).
        let start = self.out.len();
        self.out
            .extend_from_slice(zmij::Buffer::new().format_finite(x).as_bytes());
        self.spelled = [(bits, start, self.out.len() - start), self.spelled[0]];
    }
}

/// Whether `bytes` hold a quote, a backslash or a control character (below 0x20): what JSON
/// escapes. Eight bytes at a time, the last word overlapping the one before it when the
/// length is not a multiple of eight (names are 5 to 30 bytes; a byte at a time took a
/// quarter of the writer's time).
#[inline]
fn needs_escape(bytes: &[u8]) -> bool {
    const ONES: u64 = 0x0101_0101_0101_0101;
    let special = |word: u64| {
        let zero = |w: u64| w.wrapping_sub(ONES) & !w & ONES.wrapping_mul(0x80);
        // The high bit of a byte is flagged only when that byte, or one below it, is what
        // is looked for (a borrow runs upwards only): the word is flagged exactly when it
        // holds one.
        zero(word ^ ONES.wrapping_mul(u64::from(b'"')))
            | zero(word ^ ONES.wrapping_mul(u64::from(b'\\')))
            | (word.wrapping_sub(ONES.wrapping_mul(0x20)) & !word & ONES.wrapping_mul(0x80))
    };
    let word = |chunk: &[u8]| {
        let mut eight = [0u8; 8];
        eight.copy_from_slice(chunk);
        u64::from_le_bytes(eight)
    };
    if bytes.len() < 8 {
        return bytes.iter().any(|&b| b < 0x20 || b == b'"' || b == b'\\');
    }
    let mut chunks = bytes.chunks_exact(8);
    if chunks.by_ref().any(|chunk| special(word(chunk)) != 0) {
        return true;
    }
    !chunks.remainder().is_empty() && special(word(&bytes[bytes.len() - 8..])) != 0
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use std::collections::BTreeMap;

    use super::*;
    use crate::artifacts::{GraphEdge, GraphNode, GraphSpacing};
    use crate::json::to_sorted_pretty;

    /// Names with what JSON escapes (quotes, backslashes, control characters) and what it
    /// does not (non-ASCII, `/`, DEL).
    fn name() -> impl Strategy<Value = String> {
        prop_oneof![
            "[a-z_]{1,12}",
            proptest::collection::vec(
                prop_oneof![
                    Just('"'),
                    Just('\\'),
                    Just('\n'),
                    Just('\u{1}'),
                    Just('\u{1f}'),
                    Just('\u{7f}'),
                    Just('/'),
                    Just('é'),
                    Just('😀'),
                    Just('a'),
                ],
                0..6
            )
            .prop_map(|chars| chars.into_iter().collect()),
        ]
    }

    fn number() -> impl Strategy<Value = f64> {
        prop_oneof![
            any::<f64>(),
            -1e3..1e3f64,
            Just(0.0),
            Just(-0.0),
            Just(1.0),
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(1e300),
            Just(5e-324),
            // Whole numbers around the digits written without zmij, and a number that
            // repeats (the writer copies an earlier spelling of the same bits).
            (0u8..12).prop_map(f64::from),
            Just(9.000000000000002),
            Just(71.60971856124888),
        ]
    }

    fn numbers() -> impl Strategy<Value = BTreeMap<String, f64>> {
        proptest::collection::btree_map(name(), number(), 0..5)
    }

    fn artifact() -> impl Strategy<Value = GraphArtifact> {
        let node = (name(), name(), name(), any::<bool>()).prop_map(
            |(instance, is_at, face_to, container)| GraphNode {
                instance,
                is_at,
                face_to,
                container,
            },
        );
        let edge =
            (name(), name(), name(), numbers()).prop_map(|(subject, relation, object, numbers)| {
                GraphEdge {
                    subject,
                    relation,
                    object,
                    numbers,
                }
            });
        let spacing =
            (name(), name(), name(), name(), numbers()).prop_map(|(a, b, c, axis, numbers)| {
                GraphSpacing {
                    instances: [a, b, c],
                    axis,
                    numbers,
                }
            });
        (
            name(),
            name(),
            name(),
            proptest::collection::vec(node, 0..4),
            proptest::collection::vec(edge, 0..4),
            proptest::collection::vec(spacing, 0..3),
        )
            .prop_map(|(schema, scene_id, layout, nodes, edges, equally_spaced)| {
                GraphArtifact {
                    schema,
                    scene_id,
                    layout,
                    nodes,
                    edges,
                    equally_spaced,
                }
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]
        #[test]
        fn writes_the_bytes_of_the_sorted_serde_path(artifact in artifact()) {
            let expected = to_sorted_pretty(&artifact).expect("serialises");
            prop_assert_eq!(
                String::from_utf8(artifact.to_pretty_json()).expect("UTF-8"),
                String::from_utf8(expected).expect("UTF-8")
            );
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(4000))]
        /// The word-at-a-time check finds what a byte-at-a-time one finds, wherever the byte
        /// sits (first, last, in the overlap of the last two words) and whatever surrounds it
        /// (bytes above 0x7f, which the word's arithmetic must not take for small ones).
        #[test]
        fn needs_escape_is_the_byte_rule(
            body in proptest::collection::vec(
                prop_oneof![32u8..127, 128u8..=255, Just(b'"'), Just(b'\\'), 0u8..32],
                0..40,
            )
        ) {
            let bytewise = body.iter().any(|&b| b < 0x20 || b == b'"' || b == b'\\');
            prop_assert_eq!(needs_escape(&body), bytewise);
        }
    }

    /// Control: a quote, a backslash or a control byte in any place of names of every length
    /// up to 24 is found, and plain names of those lengths pass.
    #[test]
    fn needs_escape_finds_each_special_byte_in_each_place() {
        for len in 1..=24 {
            let plain = vec![b'a'; len];
            assert!(!needs_escape(&plain), "{len}");
            for at in 0..len {
                for special in [b'"', b'\\', 0x00, 0x1f, b'\n'] {
                    let mut name = plain.clone();
                    name[at] = special;
                    assert!(needs_escape(&name), "{len} {at} {special}");
                }
                let mut high = plain.clone();
                high[at] = 0xff;
                assert!(!needs_escape(&high), "{len} {at}");
            }
        }
    }

    /// Control: the comparison sees a difference of one byte (a key out of order, a float
    /// spelled otherwise), so the property above can fail.
    #[test]
    fn a_changed_artifact_gives_other_bytes() {
        let artifact = GraphArtifact {
            schema: "mesa.graph/1".into(),
            scene_id: "s".into(),
            layout: "refined/layout.json".into(),
            nodes: vec![],
            edges: vec![GraphEdge {
                subject: "a_0".into(),
                relation: "above".into(),
                object: "b_0".into(),
                numbers: [("rank".to_owned(), 1.0)].into_iter().collect(),
            }],
            equally_spaced: vec![],
        };
        let text = String::from_utf8(artifact.to_pretty_json()).expect("UTF-8");
        let expected = to_sorted_pretty(&artifact).expect("serialises");
        assert_eq!(text.as_bytes(), expected);
        assert!(text.contains("\"rank\": 1.0"), "{text}");
        let mut other = artifact.clone();
        other.edges[0]
            .numbers
            .insert("rank".into(), 1.0 + f64::EPSILON);
        assert_ne!(other.to_pretty_json(), artifact.to_pretty_json());
        let swapped = text.replace("\"object\": \"b_0\"", "\"subject\": \"a_0\"");
        assert_ne!(swapped.as_bytes(), artifact.to_pretty_json());
    }
}
