//! The built-in lexical encoder over the asset text index ([`crate::text`]): asset vectors in
//! an inverted index, so a query touches only the assets that share a feature with it.

use std::collections::HashMap;

use mesa_schemas::artifacts::TextIndexArtifact;

use crate::text::{features, LexicalModel};

/// The asset vectors of the lexical encoder.
#[derive(Debug, Clone)]
pub struct LexicalIndex {
    uids: Vec<String>,
    model: LexicalModel,
    /// Feature → (asset, weight), assets in uid order.
    postings: HashMap<String, Vec<(u32, f64)>>,
}

impl LexicalIndex {
    /// The index of a text index artifact (`assets/index/text.json`).
    pub fn new(text_index: &TextIndexArtifact) -> Self {
        let model = LexicalModel::new(
            &text_index.document_frequency,
            text_index.documents.len() as u64,
        );
        let mut postings: HashMap<String, Vec<(u32, f64)>> = HashMap::new();
        let mut uids = Vec::with_capacity(text_index.documents.len());
        // Documents are in uid order (a BTreeMap), so every posting list is too.
        for (i, (uid, document)) in text_index.documents.iter().enumerate() {
            uids.push(uid.clone());
            for (feature, weight) in model.embed(&document.features) {
                postings
                    .entry(feature)
                    .or_default()
                    .push((i as u32, weight));
            }
        }
        Self {
            uids,
            model,
            postings,
        }
    }

    /// The uid of each asset.
    pub fn uids(&self) -> &[String] {
        &self.uids
    }

    /// For each query text, the `k` assets of highest cosine, sorted by (score descending,
    /// uid ascending). A query sharing no feature with the assets scores 0 with all of them.
    pub fn top_k(&self, queries: &[&str], k: usize) -> Vec<Vec<(usize, f64)>> {
        let k = k.min(self.uids.len());
        queries
            .iter()
            .map(|text| {
                let mut scores = vec![0.0f64; self.uids.len()];
                // Features in sorted order: the sums are the same on every run.
                for (feature, weight) in self.model.embed(&features(text)) {
                    if let Some(list) = self.postings.get(&feature) {
                        for (asset, w) in list {
                            scores[*asset as usize] += weight * w;
                        }
                    }
                }
                let mut ranked: Vec<(usize, f64)> = scores.into_iter().enumerate().collect();
                // Uids are sorted, so the index order is the uid order.
                let by_score = |a: &(usize, f64), b: &(usize, f64)| {
                    b.1.total_cmp(&a.1).then_with(|| a.0.cmp(&b.0))
                };
                if k < ranked.len() && k > 0 {
                    ranked.select_nth_unstable_by(k - 1, by_score);
                }
                ranked.truncate(k);
                ranked.sort_by(by_score);
                ranked
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::annotations::Annotations;
    use crate::assets::{build_text_index, AssetsConfig};

    #[test]
    fn the_mug_comes_first_for_a_mug_query() {
        let annotations = Annotations::parse(
            r#"{"vase": {"category": "vase", "description": "A tall ceramic vase."},
                "mug": {"category": "mug", "description": "A white porcelain cup with a handle."},
                "tray": {"category": "tray", "description": "A wooden serving tray."},
                "book": {"category": "book", "description": "A red hardcover book."}}"#,
        )
        .expect("annotations");
        let index = LexicalIndex::new(&build_text_index(&annotations, &AssetsConfig::default()));
        let ranked = index.top_k(&["white ceramic coffee mug", "wooden tray", "zzz"], 2);
        assert_eq!(index.uids()[ranked[0][0].0], "mug");
        assert_eq!(index.uids()[ranked[1][0].0], "tray");
        assert!(ranked[0][0].1 > ranked[0][1].1);
        // No shared feature: every score is 0, ties by uid.
        assert_eq!(
            ranked[2].iter().map(|r| r.1).collect::<Vec<_>>(),
            [0.0, 0.0]
        );
        assert_eq!(index.uids()[ranked[2][0].0], "book");
    }
}
