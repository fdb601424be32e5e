//! The built-in lexical text encoder (`lexical/1`): deterministic, no model files, so retrieval
//! runs offline. It stands in for the official SBERT encoder (`all-mpnet-base-v2`); the
//! `features` encoder of [`crate::retrieve`] takes real SBERT embeddings computed offline.
//!
//! A text becomes a sparse vector of weighted features:
//!
//! 1. **Words**: lowercase, split on anything that is not a letter or a digit (so
//!    "blue-grey" is "blue", "grey"); words of one letter, numbers and common English stop words
//!    ("a", "with", "the", ...) are dropped; British spellings become American ("colour" →
//!    "color", "grey" → "gray"); a light stemmer removes plural endings ("mugs" → "mug",
//!    "boxes" → "box", "batteries" → "battery"). Feature `w:<word>`, weight 1 per occurrence.
//! 2. **Concepts**: a small tabletop thesaurus ([`CONCEPTS`]) maps words that name the same
//!    thing or material to one concept ("porcelain", "ceramic", "stoneware" → `ceramic`;
//!    "mug", "cup", "teacup" → `drinking_vessel`). Feature `c:<concept>`, weight 0.5 per
//!    occurrence, so synonyms match at half the strength of the same word.
//! 3. **Trigrams**: the character trigrams of each word of four letters or more, with `#`
//!    marking its ends ("wood" → `#wo`, `woo`, `ood`, `od#`). Feature `g:<trigram>`; the
//!    trigrams of one word share a weight of 0.5, so related forms ("wooden" / "wood",
//!    "striped" / "stripes") still meet.
//!
//! Each feature's weight is multiplied by its inverse document frequency over the asset texts,
//! `idf = ln((1 + N) / (1 + df)) + 1` (a feature no asset has gets `ln(1 + N) + 1`), and the
//! vector is scaled to unit length: the text score is the cosine (a dot product) of two such
//! vectors, in [0, 1].

use std::collections::BTreeMap;

/// The name of this encoder in artifacts.
pub const LEXICAL_ENCODER: &str = "lexical/1";

/// Weight of a concept feature relative to a word.
const CONCEPT_WEIGHT: f64 = 0.5;
/// Weight shared by the trigrams of one word.
const TRIGRAM_WEIGHT: f64 = 0.5;

const STOP_WORDS: &[&str] = &[
    "a", "about", "above", "across", "along", "also", "an", "and", "any", "are", "around", "as",
    "at", "be", "been", "being", "below", "between", "both", "but", "by", "can", "each", "for",
    "from", "has", "have", "in", "into", "is", "it", "its", "itself", "like", "made", "near",
    "next", "of", "off", "on", "one", "onto", "or", "other", "over", "some", "such", "that", "the",
    "their", "them", "there", "these", "this", "those", "through", "to", "top", "two", "under",
    "up", "upon", "used", "very", "was", "which", "while", "with", "within", "without",
];

/// British → American spellings (after lowercasing).
const SPELLINGS: &[(&str, &str)] = &[
    ("colour", "color"),
    ("coloured", "colored"),
    ("colours", "colors"),
    ("grey", "gray"),
    ("greyish", "grayish"),
    ("aluminium", "aluminum"),
    ("jewellery", "jewelry"),
    ("mould", "mold"),
    ("tyre", "tire"),
    ("centre", "center"),
    ("metre", "meter"),
    ("litre", "liter"),
    ("cosy", "cozy"),
];

/// The thesaurus: each concept with the (stemmed) words that name it.
pub const CONCEPTS: &[(&str, &[&str])] = &[
    (
        "ceramic",
        &[
            "ceramic",
            "porcelain",
            "china",
            "stoneware",
            "earthenware",
            "pottery",
            "terracotta",
        ],
    ),
    (
        "drinking_vessel",
        &["mug", "cup", "teacup", "tumbler", "beaker"],
    ),
    (
        "glass_material",
        &["glass", "crystal", "transparent", "clear"],
    ),
    (
        "metal",
        &[
            "metal",
            "metallic",
            "steel",
            "stainless",
            "aluminum",
            "iron",
            "brass",
            "copper",
            "chrome",
            "silver",
            "tin",
        ],
    ),
    (
        "wood",
        &[
            "wood", "wooden", "timber", "oak", "bamboo", "walnut", "pine", "beech", "birch",
        ],
    ),
    (
        "plastic",
        &["plastic", "acrylic", "polymer", "vinyl", "resin"],
    ),
    ("paper", &["paper", "cardboard", "carton", "kraft"]),
    (
        "fabric",
        &[
            "fabric", "cloth", "cotton", "linen", "textile", "felt", "wool",
        ],
    ),
    ("bowl", &["bowl", "basin", "dish"]),
    ("plate", &["plate", "platter", "saucer"]),
    ("bottle", &["bottle", "flask", "carafe", "decanter"]),
    ("jar", &["jar", "canister", "pot"]),
    ("box", &["box", "case", "container", "crate", "bin"]),
    ("book", &["book", "hardcover", "paperback", "novel"]),
    (
        "notebook",
        &["notebook", "notepad", "journal", "diary", "pad"],
    ),
    (
        "phone",
        &["phone", "smartphone", "cellphone", "mobile", "iphone"],
    ),
    (
        "computer",
        &["laptop", "notebook", "computer", "macbook", "pc"],
    ),
    ("screen", &["monitor", "screen", "display"]),
    ("keyboard", &["keyboard", "keypad"]),
    ("mouse", &["mouse", "trackpad"]),
    ("remote", &["remote", "controller"]),
    ("lamp", &["lamp", "light", "lantern"]),
    ("pen", &["pen", "pencil", "marker", "ballpoint"]),
    (
        "plant",
        &[
            "plant",
            "succulent",
            "cactus",
            "houseplant",
            "flower",
            "fern",
        ],
    ),
    ("vase", &["vase", "urn"]),
    ("candle", &["candle", "candleholder", "tealight"]),
    ("clock", &["clock", "timer"]),
    ("tray", &["tray", "board"]),
    ("soap", &["soap", "lotion", "shampoo", "cleanser", "gel"]),
    ("dispenser", &["dispenser", "pump"]),
    (
        "cosmetic",
        &[
            "cosmetic",
            "makeup",
            "lipstick",
            "perfume",
            "fragrance",
            "cologne",
        ],
    ),
    ("brush", &["brush", "comb", "toothbrush", "hairbrush"]),
    ("towel", &["towel", "napkin", "cloth"]),
    (
        "cutlery",
        &["fork", "knife", "spoon", "cutlery", "utensil", "chopstick"],
    ),
    (
        "fruit",
        &[
            "fruit", "apple", "orange", "banana", "pear", "lemon", "lime", "peach",
        ],
    ),
    (
        "food",
        &["food", "bread", "snack", "cake", "cookie", "sandwich"],
    ),
    ("kettle", &["kettle", "teapot"]),
    ("picture", &["picture", "photo", "frame", "photograph"]),
    ("speaker", &["speaker", "radio"]),
    ("headphone", &["headphone", "headset", "earphone", "earbud"]),
    ("glasses", &["eyeglass", "spectacle", "sunglass"]),
    (
        "toy",
        &["toy", "figurine", "figure", "doll", "statue", "sculpture"],
    ),
    ("small", &["small", "little", "mini", "tiny", "compact"]),
    ("large", &["large", "big", "huge", "tall", "oversized"]),
    ("round", &["round", "circular", "cylindrical", "spherical"]),
    ("square", &["square", "rectangular", "boxy"]),
    ("white", &["white", "ivory", "cream", "offwhite"]),
    ("black", &["black", "dark", "ebony", "charcoal"]),
    (
        "blue",
        &["blue", "navy", "azure", "cobalt", "teal", "turquoise"],
    ),
    ("red", &["red", "crimson", "scarlet", "burgundy", "maroon"]),
    ("green", &["green", "olive", "emerald", "mint", "sage"]),
    ("brown", &["brown", "tan", "beige", "chocolate", "walnut"]),
    ("gray", &["gray", "silver", "ash", "slate"]),
    ("yellow", &["yellow", "gold", "golden", "mustard"]),
    ("pink", &["pink", "rose", "magenta", "blush"]),
];

/// Lowercases, splits, drops stop words and numbers, normalises spelling, stems.
pub fn words(text: &str) -> Vec<String> {
    text.split(|c: char| !c.is_alphanumeric())
        .filter(|w| !w.is_empty())
        .map(str::to_lowercase)
        .filter(|w| w.chars().count() > 1 && !w.chars().all(|c| c.is_ascii_digit()))
        .filter(|w| !STOP_WORDS.contains(&w.as_str()))
        .map(|w| {
            let w = SPELLINGS
                .iter()
                .find(|(from, _)| *from == w)
                .map_or(w.clone(), |(_, to)| (*to).to_owned());
            stem(&w)
        })
        .collect()
}

/// Removes English plural endings: "-ies" → "-y" ("batteries"), "-es" after ss, x, ch, sh
/// ("glasses", "boxes", "dishes"), "-s" otherwise ("mugs", "vases"), but not "-ss" or "-us"
/// ("glass", "cactus").
pub fn stem(word: &str) -> String {
    let n = word.len();
    if n > 4 && word.ends_with("ies") && !word.ends_with("eies") && !word.ends_with("aies") {
        return format!("{}y", &word[..n - 3]);
    }
    if n > 4
        && ["sses", "xes", "ches", "shes"]
            .iter()
            .any(|end| word.ends_with(end))
    {
        return word[..n - 2].to_owned();
    }
    if n > 3 && word.ends_with('s') && !word.ends_with("ss") && !word.ends_with("us") {
        return word[..n - 1].to_owned();
    }
    word.to_owned()
}

/// The concepts a (stemmed) word belongs to.
pub fn concepts_of(word: &str) -> impl Iterator<Item = &'static str> + '_ {
    CONCEPTS
        .iter()
        .filter(move |(_, members)| members.contains(&word))
        .map(|(concept, _)| *concept)
}

/// The raw (not yet IDF-weighted) features of a text.
pub fn features(text: &str) -> BTreeMap<String, f64> {
    let mut out: BTreeMap<String, f64> = BTreeMap::new();
    for word in words(text) {
        *out.entry(format!("w:{word}")).or_default() += 1.0;
        for concept in concepts_of(&word) {
            *out.entry(format!("c:{concept}")).or_default() += CONCEPT_WEIGHT;
        }
        let chars: Vec<char> = std::iter::once('#')
            .chain(word.chars())
            .chain(std::iter::once('#'))
            .collect();
        if chars.len() >= 6 {
            let grams = chars.len() - 2;
            for window in chars.windows(3) {
                let gram: String = window.iter().collect();
                *out.entry(format!("g:{gram}")).or_default() += TRIGRAM_WEIGHT / grams as f64;
            }
        }
    }
    out
}

/// Inverse document frequencies over a set of documents' features.
#[derive(Debug, Clone, PartialEq)]
pub struct LexicalModel {
    idf: std::collections::HashMap<String, f64>,
    unseen_idf: f64,
}

impl LexicalModel {
    /// The model of `documents` documents whose features have these document frequencies.
    pub fn new(document_frequency: &BTreeMap<String, u64>, documents: u64) -> Self {
        let n = documents as f64;
        let idf = document_frequency
            .iter()
            .map(|(f, df)| (f.clone(), ((1.0 + n) / (1.0 + *df as f64)).ln() + 1.0))
            .collect();
        Self {
            idf,
            unseen_idf: (1.0 + n).ln() + 1.0,
        }
    }

    /// The unit-length IDF-weighted vector of raw features, sorted by feature; empty when the
    /// text has no feature.
    pub fn embed(&self, raw: &BTreeMap<String, f64>) -> Vec<(String, f64)> {
        let mut weighted: Vec<(String, f64)> = raw
            .iter()
            .map(|(f, w)| {
                let idf = self.idf.get(f).copied().unwrap_or(self.unseen_idf);
                (f.clone(), w * idf)
            })
            .collect();
        let norm = weighted.iter().map(|(_, w)| w * w).sum::<f64>().sqrt();
        if norm > 0.0 {
            for (_, w) in &mut weighted {
                *w /= norm;
            }
        } else {
            weighted.clear();
        }
        weighted
    }
}

/// The document frequency of each feature over these documents' features.
pub fn document_frequency<'a>(
    documents: impl IntoIterator<Item = &'a BTreeMap<String, f64>>,
) -> BTreeMap<String, u64> {
    let mut df = BTreeMap::new();
    for doc in documents {
        for feature in doc.keys() {
            *df.entry(feature.clone()).or_default() += 1;
        }
    }
    df
}

/// The cosine of two unit vectors sorted by feature (a merge join).
pub fn cosine_sorted(a: &[(String, f64)], b: &[(String, f64)]) -> f64 {
    let (mut i, mut j, mut dot) = (0, 0, 0.0);
    while i < a.len() && j < b.len() {
        match a[i].0.cmp(&b[j].0) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                dot += a[i].1 * b[j].1;
                i += 1;
                j += 1;
            }
        }
    }
    dot
}

#[cfg(test)]
mod tests {
    use super::*;

    fn score(model: &LexicalModel, a: &str, b: &str) -> f64 {
        cosine_sorted(&model.embed(&features(a)), &model.embed(&features(b)))
    }

    fn model_of(texts: &[&str]) -> LexicalModel {
        let docs: Vec<BTreeMap<String, f64>> = texts.iter().map(|t| features(t)).collect();
        LexicalModel::new(&document_frequency(&docs), docs.len() as u64)
    }

    #[test]
    fn words_are_normalised_and_stemmed() {
        assert_eq!(
            words("A Blue-Grey mug, with 2 handles; boxes & batteries in the glass"),
            ["blue", "gray", "mug", "handle", "box", "battery", "glass"]
        );
        assert_eq!(stem("dishes"), "dish");
        assert_eq!(stem("cactus"), "cactus");
        assert_eq!(stem("glasses"), "glass");
        assert_eq!(stem("plates"), "plate");
        assert_eq!(stem("vases"), "vase");
        assert_eq!(stem("boxes"), "box");
    }

    #[test]
    fn features_have_words_concepts_and_trigrams() {
        let f = features("porcelain mug");
        assert_eq!(f["w:porcelain"], 1.0);
        assert_eq!(f["c:ceramic"], 0.5);
        assert_eq!(f["c:drinking_vessel"], 0.5);
        // "#porcelain#" has 9 trigrams sharing 0.5; "mug" is too short for trigrams.
        assert!((f["g:orc"] - 0.5 / 9.0).abs() < 1e-12);
        assert!(!f.contains_key("g:mug"));
        let trigram_total: f64 = f
            .iter()
            .filter(|(k, _)| k.starts_with("g:"))
            .map(|(_, v)| v)
            .sum();
        assert!((trigram_total - 0.5).abs() < 1e-12, "{trigram_total}");
    }

    #[test]
    fn a_mug_description_prefers_the_mug() {
        // The issue's acceptance case: for a mug asset described as "a white porcelain cup
        // with a handle", "white ceramic coffee mug" ranks above "ceramic vase".
        let asset = "a white porcelain cup with a handle";
        let model = model_of(&[
            asset,
            "ceramic vase",
            "white ceramic coffee mug",
            "wooden tray",
        ]);
        let mug = score(&model, "white ceramic coffee mug", asset);
        let vase = score(&model, "ceramic vase", asset);
        assert!(mug > vase, "mug {mug} vs vase {vase}");
        assert!(mug > 0.2, "{mug}");
    }

    #[test]
    fn vectors_are_unit_and_cosines_bounded() {
        let model = model_of(&["red book", "blue book"]);
        let v = model.embed(&features("a red hardcover book"));
        let norm: f64 = v.iter().map(|(_, w)| w * w).sum::<f64>().sqrt();
        assert!((norm - 1.0).abs() < 1e-12);
        assert!((score(&model, "red book", "red book") - 1.0).abs() < 1e-12);
        assert_eq!(score(&model, "red book", "the of and"), 0.0);
        assert!(model.embed(&features("the of 12")).is_empty());
    }
}
