//! The object order both layout forms are written in (a module of its own so that [`crate::llm`]
//! and [`crate::convert`] can share it without naming each other).

/// Orders objects by descending footprint w·d, ties by instance name (the order mesa writes
/// and the published records mostly have). Returns whether the order changed.
pub fn sort_by_footprint<T>(objects: &mut [T], key: impl Fn(&T) -> (&str, [f64; 3])) -> bool {
    let before: Vec<String> = objects.iter().map(|o| key(o).0.to_owned()).collect();
    objects.sort_by(|a, b| {
        let (name_a, size_a) = key(a);
        let (name_b, size_b) = key(b);
        let fa = size_a[0] * size_a[1];
        let fb = size_b[0] * size_b[1];
        fb.total_cmp(&fa).then_with(|| name_a.cmp(name_b))
    });
    objects
        .iter()
        .map(|o| key(o).0)
        .ne(before.iter().map(String::as_str))
}
