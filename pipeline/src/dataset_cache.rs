//! What a stage reads once per dataset and run (the asset index, the annotations, the text
//! index) and shares between the scenes it processes in parallel.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use anyhow::{anyhow, bail};
use mesa_stages::annotations::Annotations;

use mesa_stages::paths::dataset::ANNOTATIONS;

/// One value per dataset folder, loaded by the first scene that asks for it; a load that
/// failed is remembered, and every later scene fails with the same message without retrying.
pub struct DatasetCache<T> {
    entries: Mutex<BTreeMap<PathBuf, Result<Arc<T>, String>>>,
}

impl<T> Default for DatasetCache<T> {
    fn default() -> Self {
        Self {
            entries: Mutex::new(BTreeMap::new()),
        }
    }
}

impl<T> DatasetCache<T> {
    /// The value of `dataset`, loaded with `load` if no scene has asked for it yet (the lock is
    /// held while loading, so a dataset is loaded once).
    pub fn get_or_load(
        &self,
        dataset: &Path,
        load: impl FnOnce() -> anyhow::Result<T>,
    ) -> anyhow::Result<Arc<T>> {
        let mut entries = self
            .entries
            .lock()
            .map_err(|_| anyhow!("internal error: the dataset cache is poisoned"))?;
        let entry = entries
            .entry(dataset.to_owned())
            .or_insert_with(|| load().map(Arc::new).map_err(|e| format!("{e:#}")));
        match entry {
            Ok(value) => Ok(Arc::clone(value)),
            Err(message) => bail!("{message}"),
        }
    }
}

/// The dataset's `assets/annotations.json`, or no annotations when it has none.
pub fn read_annotations(dataset: &Path) -> anyhow::Result<Annotations> {
    let path = dataset.join(ANNOTATIONS);
    Ok(if path.exists() {
        Annotations::read(&path)?
    } else {
        Annotations::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::Cell;

    #[test]
    fn loads_once_per_dataset_and_remembers_failures() {
        let cache = DatasetCache::<u32>::default();
        let loads = Cell::new(0);
        let load = |value: u32| {
            loads.set(loads.get() + 1);
            Ok(value)
        };
        assert_eq!(
            *cache
                .get_or_load(Path::new("a"), || load(1))
                .expect("loads"),
            1
        );
        assert_eq!(
            *cache
                .get_or_load(Path::new("a"), || load(2))
                .expect("loads"),
            1
        );
        assert_eq!(
            *cache
                .get_or_load(Path::new("b"), || load(3))
                .expect("loads"),
            3
        );
        assert_eq!(loads.get(), 2);
        let failing = || -> anyhow::Result<u32> { bail!("index.json: missing") };
        let first = cache
            .get_or_load(Path::new("c"), failing)
            .expect_err("fails");
        let again = cache
            .get_or_load(Path::new("c"), || load(4))
            .expect_err("fails");
        assert_eq!(first.to_string(), "index.json: missing");
        assert_eq!(again.to_string(), first.to_string());
        assert_eq!(loads.get(), 2);
    }
}
