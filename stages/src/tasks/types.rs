//! Object types: how an instance name (`desk_lamp_0`) becomes the type a task names
//! (`Desk Lamp`), and how a type written by a model is matched back to the scene's objects.
//!
//! Tasks name object types, never instances (SPEC 5.8). Models write types in their own way
//! ("Lotion Bottles", "dinner plates"), so matching works on a normalised key: lower case,
//! words separated by single spaces, the last word made singular. A written type matches a
//! scene type when the keys are equal or, failing that, when one key ends with the other as
//! whole words ("Potted Plant" matches `plant`, "Dinner Plates" matches `plates`).

use mesa_schemas::convert::category_of_instance;
use mesa_schemas::LlmLayout;

/// One object type of a scene.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObjectType {
    /// The name tasks and reasoning texts use: the category in title case, like `Desk Lamp`.
    pub name: String,
    /// The normalised key, like `desk lamp`.
    pub key: String,
    /// The instances of this type, in layout order.
    pub instances: Vec<String>,
}

impl ObjectType {
    /// How many objects of this type the scene has.
    pub fn count(&self) -> usize {
        self.instances.len()
    }

    /// `Name(count)`, the form of the reasoning lists.
    pub fn with_count(&self) -> String {
        format!("{}({})", self.name, self.count())
    }
}

/// The object types of a scene, in the layout order of their first instance.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SceneTypes {
    /// The types.
    pub types: Vec<ObjectType>,
}

impl SceneTypes {
    /// The types of a layout's objects. Categories whose keys coincide (`lotion_bottle` and
    /// `lotion_bottles`) are one type.
    pub fn of_layout(layout: &LlmLayout) -> Self {
        Self::of_instances(layout.objects.iter().map(|o| o.instance.as_str()))
    }

    /// The types of instance names, in the given order.
    pub fn of_instances<'a>(instances: impl IntoIterator<Item = &'a str>) -> Self {
        let mut types: Vec<ObjectType> = Vec::new();
        for instance in instances {
            let category = category_of_instance(instance);
            let key = type_key(category);
            match types.iter_mut().find(|t| t.key == key) {
                Some(t) => t.instances.push(instance.to_owned()),
                None => types.push(ObjectType {
                    name: display_name(category),
                    key,
                    instances: vec![instance.to_owned()],
                }),
            }
        }
        Self { types }
    }

    /// Total number of objects.
    pub fn object_count(&self) -> usize {
        self.types.iter().map(ObjectType::count).sum()
    }

    /// The scene types a written type name refers to: the one with an equal key, else every
    /// type whose key ends with the written key as whole words or whose key the written key
    /// ends with. Empty when nothing matches.
    pub fn matching(&self, written: &str) -> Vec<&ObjectType> {
        let key = type_key(written);
        if key.is_empty() {
            return Vec::new();
        }
        if let Some(exact) = self.types.iter().find(|t| t.key == key) {
            return vec![exact];
        }
        self.types
            .iter()
            .filter(|t| ends_with_words(&t.key, &key) || ends_with_words(&key, &t.key))
            .collect()
    }

    /// `Name(count), Name(count)` of the given types, or `None` when there are none.
    pub fn list<'a>(types: impl IntoIterator<Item = &'a ObjectType>) -> String {
        let items: Vec<String> = types.into_iter().map(ObjectType::with_count).collect();
        if items.is_empty() {
            "None".to_owned()
        } else {
            items.join(", ")
        }
    }
}

/// Whether `long` is `short` or ends with `" " + short`.
fn ends_with_words(long: &str, short: &str) -> bool {
    long == short
        || long
            .strip_suffix(short)
            .is_some_and(|head| head.ends_with(' '))
}

/// The display name of a category: words in title case, `desk_lamp` → `Desk Lamp`.
pub fn display_name(category: &str) -> String {
    category
        .split(['_', '-', ' '])
        .filter(|w| !w.is_empty())
        .map(|w| {
            let mut chars = w.chars();
            match chars.next() {
                Some(first) => first.to_uppercase().chain(chars).collect::<String>(),
                None => String::new(),
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// The normalised key of a type name: lower case, `_`/`-` as spaces, single spaces, the last
/// word singular (`Lotion Bottles` → `lotion bottle`).
pub fn type_key(name: &str) -> String {
    let lower = name.to_lowercase();
    let mut words: Vec<&str> = lower
        .split(|c: char| c == '_' || c == '-' || c.is_whitespace())
        .filter(|w| !w.is_empty())
        .collect();
    let Some(last) = words.pop() else {
        return String::new();
    };
    let singular = singular(last);
    words.push(&singular);
    words.join(" ")
}

/// A word made singular by the common English rules (enough for object nouns).
pub fn singular(word: &str) -> String {
    const IRREGULAR: [(&str, &str); 12] = [
        ("knives", "knife"),
        ("leaves", "leaf"),
        ("shelves", "shelf"),
        ("loaves", "loaf"),
        ("halves", "half"),
        ("scarves", "scarf"),
        ("people", "person"),
        ("mice", "mouse"),
        ("geese", "goose"),
        ("teeth", "tooth"),
        ("feet", "foot"),
        ("dice", "die"),
    ];
    if let Some((_, one)) = IRREGULAR.iter().find(|(many, _)| *many == word) {
        return (*one).to_owned();
    }
    if word.len() > 4 {
        if let Some(stem) = word.strip_suffix("ies") {
            return format!("{stem}y");
        }
    }
    for ending in ["ches", "shes", "sses", "xes", "zes", "oes"] {
        if word.len() > ending.len() + 1 && word.ends_with(ending) {
            return word[..word.len() - 2].to_owned();
        }
    }
    if word.len() > 3
        && word.ends_with('s')
        && !["ss", "us", "is"].iter().any(|e| word.ends_with(e))
    {
        return word[..word.len() - 1].to_owned();
    }
    word.to_owned()
}

/// The plural of a word for prose (`mug` → `mugs`, `glass` → `glasses`, `candy` → `candies`).
pub fn plural(word: &str) -> String {
    let vowels = ['a', 'e', 'i', 'o', 'u'];
    if let Some(stem) = word.strip_suffix('y') {
        if !stem.ends_with(vowels) && !stem.is_empty() {
            return format!("{stem}ies");
        }
    }
    if ["s", "x", "z", "ch", "sh"]
        .iter()
        .any(|e| word.ends_with(e))
    {
        return format!("{word}es");
    }
    format!("{word}s")
}

/// Whether a name looks like an instance name (`desk_lamp_0`, `mug_12`) rather than a type.
pub fn looks_like_instance(name: &str) -> bool {
    let name = name.trim();
    match name.rsplit_once('_') {
        Some((stem, index)) => {
            !stem.is_empty()
                && !index.is_empty()
                && index.bytes().all(|b| b.is_ascii_digit())
                && !stem.contains(' ')
        }
        None => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_normalise_case_separators_and_plurals() {
        assert_eq!(type_key("Lotion Bottles"), "lotion bottle");
        assert_eq!(type_key("lotion_bottle"), "lotion bottle");
        assert_eq!(type_key("Dishes"), "dish");
        assert_eq!(type_key("glasses"), "glass");
        assert_eq!(type_key("Candies"), "candy");
        assert_eq!(type_key("knives"), "knife");
        assert_eq!(type_key("Fruit"), "fruit");
        assert_eq!(type_key("bus"), "bus");
        assert_eq!(type_key("  "), "");
        assert_eq!(display_name("desk_lamp"), "Desk Lamp");
        assert_eq!(plural("candy"), "candies");
        assert_eq!(plural("glass"), "glasses");
        assert_eq!(plural("tray"), "trays");
    }

    #[test]
    fn written_types_match_exactly_first_then_by_trailing_words() {
        let types = SceneTypes::of_instances([
            "plates_0",
            "plate_1",
            "book_0",
            "notebook_book_0",
            "plant_0",
        ]);
        // `plates` and `plate` share a key: one type with two objects.
        assert_eq!(types.types.len(), 4);
        assert_eq!(types.types[0].count(), 2);
        let names =
            |w: &str| -> Vec<String> { types.matching(w).iter().map(|t| t.name.clone()).collect() };
        assert_eq!(names("Dinner Plates"), ["Plates"]);
        assert_eq!(names("Book"), ["Book"]);
        assert_eq!(names("Notebook Book"), ["Notebook Book"]);
        assert_eq!(names("Potted Plant"), ["Plant"]);
        assert!(names("Lamp").is_empty());
    }

    #[test]
    fn instance_names_are_told_from_types() {
        assert!(looks_like_instance("desk_lamp_0"));
        assert!(looks_like_instance("mug_12"));
        assert!(!looks_like_instance("Desk Lamp"));
        assert!(!looks_like_instance("mug"));
        assert!(!looks_like_instance("cup holder_1x"));
    }
}
