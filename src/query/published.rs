//! What DataFusion may list: a run's published files, and nothing else.
//!
//! DataFusion's listing tables ask their runtime's *list files cache* before they list a folder.
//! [`PublishedFiles`] is such a cache that never misses: it answers every table folder of the run with
//! the files [`RunDir::tables`](crate::store::RunDir::tables) returned — the outputs of the manifest's
//! finished stages, sizes checked — and any other folder with no files. So a query never sees a file of
//! an unfinished commit or a foreign file dropped into a table folder, and no folder is listed while a
//! query runs (the same would carry over to an object store, where listing is expensive).
//!
//! **Owns:** that cache. **Does not:** decide which files are published (`store`), or register tables
//! (`RunQuery::open_with`).

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use datafusion::common::TableReference;
use datafusion::datasource::listing::ListingTableUrl;
use datafusion::error::DataFusionError;
use datafusion::execution::cache::cache_manager::CachedFileList;
use datafusion::execution::cache::{Cache, CacheEntryInfo, TableScopedPath};
use datafusion::object_store::ObjectMeta;
use datafusion::object_store::path::Path as StorePath;

use crate::store::TableDir;

/// The URL DataFusion registers a table folder under (absolute, ending in `/`).
pub(crate) fn folder_url(dir: &std::path::Path) -> Result<String, std::io::Error> {
    let mut url = std::path::absolute(dir)?.to_string_lossy().into_owned();
    if !url.ends_with('/') {
        url.push('/');
    }
    Ok(url)
}

/// A list files cache holding exactly the published files of each table folder.
#[derive(Debug, Default)]
pub(crate) struct PublishedFiles {
    folders: HashMap<StorePath, CachedFileList>,
}

impl PublishedFiles {
    /// The listing of `tables`, keyed as DataFusion keys a listing table's folder.
    pub fn new(tables: &[(std::path::PathBuf, &TableDir)]) -> Result<Self, DataFusionError> {
        let mut folders = HashMap::new();
        for (dir, table) in tables {
            let url = folder_url(dir).map_err(|e| DataFusionError::External(Box::new(e)))?;
            let key = ListingTableUrl::parse(&url)?.prefix().clone();
            let mut files = Vec::with_capacity(table.files.len());
            for f in &table.files {
                let abs = std::path::absolute(&f.path)
                    .map_err(|e| DataFusionError::External(Box::new(e)))?;
                let location = ListingTableUrl::parse(abs.to_string_lossy())?
                    .prefix()
                    .clone();
                files.push(ObjectMeta {
                    location,
                    last_modified: f.modified.into(),
                    size: f.bytes,
                    e_tag: None,
                    version: None,
                });
            }
            folders.insert(key, CachedFileList::new(files));
        }
        Ok(PublishedFiles { folders })
    }
}

impl Cache<TableScopedPath, CachedFileList> for PublishedFiles {
    /// The published files of a table folder; an empty list for any other folder, so DataFusion never
    /// lists the file system itself.
    fn get(&self, key: &TableScopedPath) -> Option<CachedFileList> {
        Some(
            self.folders
                .get(&key.path)
                .cloned()
                .unwrap_or_else(|| CachedFileList::new(Vec::new())),
        )
    }

    /// Ignored: the listing is fixed when the session opens.
    fn put(&self, _key: &TableScopedPath, _value: CachedFileList) -> Option<CachedFileList> {
        None
    }

    fn remove(&self, _key: &TableScopedPath) -> Option<CachedFileList> {
        None
    }

    fn contains_key(&self, _key: &TableScopedPath) -> bool {
        true
    }

    fn len(&self) -> usize {
        self.folders.len()
    }

    fn clear(&self) {}

    fn name(&self) -> String {
        "annotrace published files".to_string()
    }

    fn cache_limit(&self) -> usize {
        usize::MAX
    }

    fn update_cache_limit(&self, _limit: usize) {}

    fn cache_ttl(&self) -> Option<Duration> {
        None
    }

    fn update_cache_ttl(&self, _ttl: Option<Duration>) {}

    fn drop_table_entries(&self, _table_ref: &TableReference) -> datafusion::error::Result<()> {
        Ok(())
    }

    fn list_entries(
        &self,
    ) -> datafusion::common::HashMap<TableScopedPath, CacheEntryInfo<CachedFileList>> {
        self.folders
            .iter()
            .map(|(path, files)| {
                (
                    TableScopedPath {
                        table: None,
                        path: path.clone(),
                    },
                    CacheEntryInfo {
                        value: files.clone(),
                        size_bytes: 0,
                        hits: 0,
                        expires: None,
                    },
                )
            })
            .collect()
    }
}

/// Shares the cache with DataFusion's runtime.
pub(crate) fn shared(
    files: PublishedFiles,
) -> Arc<datafusion::execution::cache::cache_manager::ListFilesCache> {
    Arc::new(files)
}
