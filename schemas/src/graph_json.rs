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
use crate::pretty::Pretty;

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
    let mut w = Pretty::with_capacity(1024 + 480 * edges.len() + 160 * nodes.len());
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
    w.into_bytes()
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

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use std::collections::BTreeMap;

    use super::*;
    use crate::artifacts::{GraphEdge, GraphNode, GraphSpacing};
    use crate::json::to_sorted_pretty;
    use crate::pretty::tests::text as name;

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
