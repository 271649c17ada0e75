//! Durable, versioned map storage in an embedded `redb` database (one file, no server).
//!
//! Layout (file `maps.redb` in the data directory):
//!
//! | table | key | value |
//! |---|---|---|
//! | `map_meta` | map id | JSON [`MapRecord`]: the [`MapMeta`] and where the map came from |
//! | `map_cells_lz4` | map id | the cells, row-major, row 0 at the bottom, as one LZ4 block |
//! | `map_cells` | map id | the same uncompressed: what stores written before LZ4 hold; read, never written |
//! | `map_versions` | (name, version) | map id |
//!
//! Floor plans are long runs of free, occupied and unknown cells: LZ4 stores the 100 M cells of a
//! 20000 × 5000 plan in well under 1 % of their size, and decompresses them at memory speed. The
//! block carries no length; the metadata's width × height is the only size trusted on reading,
//! so a damaged record cannot make a reader allocate more than the map's cells.
//!
//! Every [`MapStore::put`] is one redb write transaction with immediate durability: redb's
//! copy-on-write commit makes a crash in the middle of a write (power loss, SIGKILL, abort)
//! leave the previous committed state, and a committed version survives any restart. The
//! version number is chosen inside that transaction, so concurrent writers in one process
//! serialize and never hand out the same number twice.
//!
//! Ids are content addressed: `<name>-<first 12 hex of sha256>` over the width, height,
//! resolution, origin and cells ([`content_hash`]). Putting content that is identical to a
//! version already stored under the same name stores nothing and returns that version's
//! metadata, because one id must name exactly one version.
//!
//! redb locks the file: one process at a time opens a data directory.

use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use protocol::{MapGrid, MapId, MapMeta, MapName, Pose2D};
use redb::{Database, ReadableTable, TableDefinition};
use serde::{Deserialize, Serialize};

use crate::error::MapError;
use crate::grid::OccupancyGrid;

const META: TableDefinition<&str, &[u8]> = TableDefinition::new("map_meta");
/// Raw cells of stores written before compression; read only.
const CELLS: TableDefinition<&str, &[u8]> = TableDefinition::new("map_cells");
const CELLS_LZ4: TableDefinition<&str, &[u8]> = TableDefinition::new("map_cells_lz4");
const VERSIONS: TableDefinition<(&str, u32), &str> = TableDefinition::new("map_versions");

/// File name of the database inside the data directory.
pub const DB_FILE: &str = "maps.redb";

/// What kind of input a stored map was made from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SourceKind {
    /// A ROS `map_server` YAML + image.
    RosMap,
    /// A plain floor-plan picture with a given scale.
    Picture,
    /// A grid handed over in memory (upload API, tests, generated worlds).
    Grid,
}

/// Where a stored map came from; kept beside its metadata for humans and audits.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapSource {
    pub kind: SourceKind,
    /// The file it was imported from, if any.
    pub path: Option<String>,
    /// Free text, e.g. the thresholds used.
    pub note: String,
}

impl MapSource {
    #[must_use]
    pub fn new(kind: SourceKind, path: Option<&Path>, note: impl Into<String>) -> Self {
        Self {
            kind,
            path: path.map(|p| p.display().to_string()),
            note: note.into(),
        }
    }
}

/// The JSON value of the `map_meta` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapRecord {
    pub meta: MapMeta,
    pub source: MapSource,
}

/// One stored version with its cells.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredMap {
    pub meta: MapMeta,
    pub source: MapSource,
    pub grid: OccupancyGrid,
}

impl StoredMap {
    /// The wire form served to robots.
    #[must_use]
    pub fn to_map_grid(&self) -> MapGrid {
        MapGrid {
            meta: self.meta.clone(),
            cells: self.grid.cells().to_vec(),
        }
    }
}

/// The grid's content hash ([`OccupancyGrid::content_hash`]), which names its stored version.
#[must_use]
pub fn content_hash(grid: &OccupancyGrid) -> String {
    grid.content_hash()
}

/// The versioned map database.
#[derive(Debug)]
pub struct MapStore {
    db: Database,
    path: PathBuf,
}

impl MapStore {
    /// Opens (creating if needed) the store in `data_dir`.
    ///
    /// # Errors
    /// [`MapError::Io`] if the folder cannot be created, [`MapError::Store`] if the database
    /// cannot be opened (e.g. another process holds it).
    pub fn open(data_dir: &Path) -> Result<Self, MapError> {
        std::fs::create_dir_all(data_dir).map_err(|e| MapError::io(data_dir, e))?;
        let path = data_dir.join(DB_FILE);
        let db = Database::create(&path).map_err(|e| MapError::store("open", e))?;
        // Create the tables once so readers never see "table does not exist".
        let txn = db
            .begin_write()
            .map_err(|e| MapError::store("begin write", e))?;
        {
            txn.open_table(META)
                .map_err(|e| MapError::store("open table", e))?;
            txn.open_table(CELLS)
                .map_err(|e| MapError::store("open table", e))?;
            txn.open_table(CELLS_LZ4)
                .map_err(|e| MapError::store("open table", e))?;
            txn.open_table(VERSIONS)
                .map_err(|e| MapError::store("open table", e))?;
        }
        txn.commit().map_err(|e| MapError::store("commit", e))?;
        Ok(Self { db, path })
    }

    /// The database file.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Stores `grid` as the next version of `name` (version 1 for a new name) and returns its
    /// metadata; identical content already stored under `name` returns that version instead.
    ///
    /// # Errors
    /// [`MapError::Store`] if the transaction fails; then nothing was stored.
    pub fn put(
        &self,
        name: &MapName,
        grid: &OccupancyGrid,
        source: &MapSource,
    ) -> Result<MapMeta, MapError> {
        // Hashing happens inside the transaction on purpose: the version check and the insert
        // must see the same state.
        let txn = self
            .db
            .begin_write()
            .map_err(|e| MapError::store("begin write", e))?;
        let hash = content_hash(grid);
        let id = MapId::from_name_and_hash(name, &hash)?;
        let meta = {
            let mut meta_t = txn
                .open_table(META)
                .map_err(|e| MapError::store("open table", e))?;
            if let Some(existing) = meta_t
                .get(id.as_str())
                .map_err(|e| MapError::store("read", e))?
            {
                let record = decode_record(existing.value())?;
                return Ok(record.meta);
            }
            let mut versions_t = txn
                .open_table(VERSIONS)
                .map_err(|e| MapError::store("open table", e))?;
            let latest = versions_t
                .range((name.as_str(), 0)..=(name.as_str(), u32::MAX))
                .map_err(|e| MapError::store("read", e))?
                .next_back()
                .transpose()
                .map_err(|e| MapError::store("read", e))?
                .map(|(k, _)| k.value().1);
            let version = match latest {
                None => 1,
                Some(v) => v.checked_add(1).ok_or_else(|| {
                    MapError::invalid("version", v, "no further version number available")
                })?,
            };
            let counts = grid.counts();
            let meta = MapMeta {
                id: id.clone(),
                name: name.clone(),
                version,
                content_hash: hash,
                width_cells: grid.width_cells(),
                height_cells: grid.height_cells(),
                resolution_m: grid.resolution_m(),
                origin: grid.origin(),
                free_cells: counts.free,
                occupied_cells: counts.occupied,
                unknown_cells: counts.unknown,
                created_ns: now_ns(),
            };
            let record = MapRecord {
                meta: meta.clone(),
                source: source.clone(),
            };
            let json = serde_json::to_vec(&record).map_err(|e| MapError::store("encode", e))?;
            meta_t
                .insert(id.as_str(), json.as_slice())
                .map_err(|e| MapError::store("write", e))?;
            let mut cells_t = txn
                .open_table(CELLS_LZ4)
                .map_err(|e| MapError::store("open table", e))?;
            let block = lz4_flex::block::compress(grid.cells());
            cells_t
                .insert(id.as_str(), block.as_slice())
                .map_err(|e| MapError::store("write", e))?;
            versions_t
                .insert((name.as_str(), version), id.as_str())
                .map_err(|e| MapError::store("write", e))?;
            meta
        };
        txn.commit().map_err(|e| MapError::store("commit", e))?;
        Ok(meta)
    }

    /// The metadata of `name` at `version`, or of its latest version.
    ///
    /// # Errors
    /// [`MapError::NotFound`] naming the map (and version), [`MapError::Store`].
    pub fn meta(&self, name: &MapName, version: Option<u32>) -> Result<MapMeta, MapError> {
        let id = self.resolve(name, version)?;
        Ok(self.record(&id)?.meta)
    }

    /// `name` at `version`, or its latest version, with cells.
    ///
    /// # Errors
    /// [`MapError::NotFound`] naming the map (and version), [`MapError::Store`].
    pub fn get(&self, name: &MapName, version: Option<u32>) -> Result<StoredMap, MapError> {
        let id = self.resolve(name, version)?;
        self.get_by_id(&id)
    }

    /// One stored version by its content-addressed id.
    ///
    /// # Errors
    /// [`MapError::NotFound`] naming the id, [`MapError::Store`] if the record is damaged.
    pub fn get_by_id(&self, id: &MapId) -> Result<StoredMap, MapError> {
        let txn = self
            .db
            .begin_read()
            .map_err(|e| MapError::store("begin read", e))?;
        let meta_t = txn
            .open_table(META)
            .map_err(|e| MapError::store("open table", e))?;
        let record = meta_t
            .get(id.as_str())
            .map_err(|e| MapError::store("read", e))?
            .map(|g| decode_record(g.value()))
            .transpose()?
            .ok_or_else(|| MapError::NotFound {
                what: format!("with id {id}"),
            })?;
        let m = &record.meta;
        let cells = read_cells(&txn, id, m)?;
        let grid = OccupancyGrid::new(
            m.width_cells,
            m.height_cells,
            m.resolution_m,
            Pose2D::new(m.origin.x_m, m.origin.y_m, m.origin.yaw_rad),
            cells,
        )?;
        Ok(StoredMap {
            meta: record.meta,
            source: record.source,
            grid,
        })
    }

    /// Bytes the database file takes on disk.
    ///
    /// # Errors
    /// [`MapError::Io`].
    pub fn file_bytes(&self) -> Result<u64, MapError> {
        Ok(std::fs::metadata(&self.path)
            .map_err(|e| MapError::io(&self.path, e))?
            .len())
    }

    /// Every stored version, sorted by name, newest version first within a name.
    ///
    /// # Errors
    /// [`MapError::Store`].
    pub fn list(&self) -> Result<Vec<MapMeta>, MapError> {
        let txn = self
            .db
            .begin_read()
            .map_err(|e| MapError::store("begin read", e))?;
        let meta_t = txn
            .open_table(META)
            .map_err(|e| MapError::store("open table", e))?;
        let mut out = Vec::new();
        for entry in meta_t.iter().map_err(|e| MapError::store("read", e))? {
            let (_, v) = entry.map_err(|e| MapError::store("read", e))?;
            out.push(decode_record(v.value())?.meta);
        }
        out.sort_by(|a, b| a.name.cmp(&b.name).then(b.version.cmp(&a.version)));
        Ok(out)
    }

    /// The versions of `name`, oldest first; empty if the name is unknown.
    ///
    /// # Errors
    /// [`MapError::Store`].
    pub fn versions(&self, name: &MapName) -> Result<Vec<MapMeta>, MapError> {
        let ids: Vec<MapId> = {
            let txn = self
                .db
                .begin_read()
                .map_err(|e| MapError::store("begin read", e))?;
            let t = txn
                .open_table(VERSIONS)
                .map_err(|e| MapError::store("open table", e))?;
            let range = t
                .range((name.as_str(), 0)..=(name.as_str(), u32::MAX))
                .map_err(|e| MapError::store("read", e))?;
            let mut ids = Vec::new();
            for entry in range {
                let (_, v) = entry.map_err(|e| MapError::store("read", e))?;
                ids.push(MapId::new(v.value())?);
            }
            ids
        };
        ids.iter()
            .map(|id| self.record(id).map(|r| r.meta))
            .collect()
    }

    /// Looks up a map by id first, else by name (latest version): what the CLI accepts.
    ///
    /// # Errors
    /// [`MapError::NotFound`], [`MapError::Store`].
    pub fn find(&self, id_or_name: &str) -> Result<StoredMap, MapError> {
        if let Ok(id) = MapId::new(id_or_name) {
            match self.get_by_id(&id) {
                Err(MapError::NotFound { .. }) => {}
                other => return other,
            }
        }
        let name = MapName::new(id_or_name)?;
        self.get(&name, None)
    }

    fn resolve(&self, name: &MapName, version: Option<u32>) -> Result<MapId, MapError> {
        let txn = self
            .db
            .begin_read()
            .map_err(|e| MapError::store("begin read", e))?;
        let t = txn
            .open_table(VERSIONS)
            .map_err(|e| MapError::store("open table", e))?;
        let found = match version {
            Some(v) => t
                .get((name.as_str(), v))
                .map_err(|e| MapError::store("read", e))?
                .map(|g| g.value().to_string()),
            None => t
                .range((name.as_str(), 0)..=(name.as_str(), u32::MAX))
                .map_err(|e| MapError::store("read", e))?
                .next_back()
                .transpose()
                .map_err(|e| MapError::store("read", e))?
                .map(|(_, v)| v.value().to_string()),
        };
        let id = found.ok_or_else(|| MapError::NotFound {
            what: match version {
                Some(v) => format!("named {name} with version {v}"),
                None => format!("named {name}"),
            },
        })?;
        Ok(MapId::new(id)?)
    }

    fn record(&self, id: &MapId) -> Result<MapRecord, MapError> {
        let txn = self
            .db
            .begin_read()
            .map_err(|e| MapError::store("begin read", e))?;
        let t = txn
            .open_table(META)
            .map_err(|e| MapError::store("open table", e))?;
        t.get(id.as_str())
            .map_err(|e| MapError::store("read", e))?
            .map(|g| decode_record(g.value()))
            .transpose()?
            .ok_or_else(|| MapError::NotFound {
                what: format!("with id {id}"),
            })
    }
}

/// The cells of `id`: the LZ4 block, or the raw cells of a store written before compression,
/// exactly `width × height` of them.
fn read_cells(
    txn: &redb::ReadTransaction,
    id: &MapId,
    meta: &MapMeta,
) -> Result<Vec<u8>, MapError> {
    let len = usize::try_from(u64::from(meta.width_cells) * u64::from(meta.height_cells))
        .map_err(|e| MapError::store("read", format!("cells of {id}: {e}")))?;
    let lz4_t = txn
        .open_table(CELLS_LZ4)
        .map_err(|e| MapError::store("open table", e))?;
    if let Some(block) = lz4_t
        .get(id.as_str())
        .map_err(|e| MapError::store("read", e))?
    {
        let mut cells = vec![0u8; len];
        let n = lz4_flex::block::decompress_into(block.value(), &mut cells)
            .map_err(|e| MapError::store("read", format!("cells of {id} are damaged: {e}")))?;
        if n != len {
            return Err(MapError::store(
                "read",
                format!("cells of {id} are damaged: {n} cells where {len} were stored"),
            ));
        }
        return Ok(cells);
    }
    let raw_t = txn
        .open_table(CELLS)
        .map_err(|e| MapError::store("open table", e))?;
    let raw = raw_t
        .get(id.as_str())
        .map_err(|e| MapError::store("read", e))?
        .map(|g| g.value().to_vec())
        .ok_or_else(|| MapError::store("read", format!("cells of {id} are missing")))?;
    Ok(raw)
}

fn decode_record(bytes: &[u8]) -> Result<MapRecord, MapError> {
    serde_json::from_slice(bytes).map_err(|e| MapError::store("decode record", e))
}

fn now_ns() -> u64 {
    // A clock before 1970 is a broken host; 0 still orders before every real stamp.
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{FREE, OCCUPIED, UNKNOWN};

    fn grid(seed: u8) -> OccupancyGrid {
        let cells: Vec<u8> = (0..40u32 * 30)
            .map(|i| match (i + u32::from(seed)) % 7 {
                0 => OCCUPIED,
                1 => UNKNOWN,
                _ => FREE,
            })
            .collect();
        OccupancyGrid::new(40, 30, 0.05, Pose2D::new(-1.0, 2.0, 0.5), cells).unwrap()
    }

    fn src() -> MapSource {
        MapSource::new(SourceKind::Grid, None, "unit test")
    }

    #[test]
    fn versions_ids_and_dedup() {
        let dir = tempfile::tempdir().unwrap();
        let store = MapStore::open(dir.path()).unwrap();
        let name = MapName::new("office").unwrap();
        let m1 = store.put(&name, &grid(0), &src()).unwrap();
        let m2 = store.put(&name, &grid(1), &src()).unwrap();
        assert_eq!((m1.version, m2.version), (1, 2));
        assert_eq!(
            m1.id.as_str(),
            format!("office-{}", &content_hash(&grid(0))[..12])
        );
        assert_ne!(m1.id, m2.id);
        // Same content again: the existing version, nothing new stored.
        let again = store.put(&name, &grid(0), &src()).unwrap();
        assert_eq!(again, m1);
        assert_eq!(store.versions(&name).unwrap(), vec![m1.clone(), m2.clone()]);
        assert_eq!(store.get(&name, None).unwrap().meta, m2);
        assert_eq!(store.get(&name, Some(1)).unwrap().grid, grid(0));
        assert_eq!(store.get_by_id(&m2.id).unwrap().grid, grid(1));
        assert_eq!(store.find(m1.id.as_str()).unwrap().meta, m1);
        assert_eq!(store.find("office").unwrap().meta, m2);
        let other = MapName::new("lab").unwrap();
        let m3 = store.put(&other, &grid(0), &src()).unwrap();
        assert_eq!(m3.version, 1);
        let names: Vec<(String, u32)> = store
            .list()
            .unwrap()
            .into_iter()
            .map(|m| (m.name.to_string(), m.version))
            .collect();
        assert_eq!(
            names,
            [
                ("lab".into(), 1),
                ("office".into(), 2),
                ("office".into(), 1)
            ]
        );
        let c = grid(0).counts();
        assert_eq!(
            (m1.free_cells, m1.occupied_cells, m1.unknown_cells),
            (c.free, c.occupied, c.unknown)
        );
    }

    /// A 4000 × 2500 floor plan (10 M cells: rooms of free space in walls, unknown outside)
    /// goes to disk as LZ4 and comes back cell for cell.
    #[test]
    fn grids_are_stored_compressed_and_read_back_exactly() {
        let (w, h) = (4000u32, 2500u32);
        let cells: Vec<u8> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                if x < 100 || y < 100 {
                    UNKNOWN
                } else if x % 500 < 3 || y % 400 < 3 {
                    OCCUPIED
                } else {
                    FREE
                }
            })
            .collect();
        let plan = OccupancyGrid::new(w, h, 0.01, Pose2D::new(0.0, 0.0, 0.0), cells).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let store = MapStore::open(dir.path()).unwrap();
        let name = MapName::new("big").unwrap();
        let before = store.file_bytes().unwrap();
        store.put(&name, &plan, &src()).unwrap();
        let grew = store.file_bytes().unwrap() - before;
        assert!(grew < 2_000_000, "10 M cells took {grew} bytes on disk");
        let back = store.get(&name, None).unwrap();
        assert_eq!(back.grid.cells(), plan.cells());
    }

    /// Stores written before compression keep raw cells in `map_cells`; they still read.
    #[test]
    fn raw_cells_of_older_stores_still_read() {
        let dir = tempfile::tempdir().unwrap();
        let store = MapStore::open(dir.path()).unwrap();
        let name = MapName::new("old").unwrap();
        let g = grid(3);
        let meta = store.put(&name, &g, &src()).unwrap();
        // Rewrite the record the way the earlier layout held it.
        let txn = store.db.begin_write().unwrap();
        {
            txn.open_table(CELLS_LZ4)
                .unwrap()
                .remove(meta.id.as_str())
                .unwrap();
            txn.open_table(CELLS)
                .unwrap()
                .insert(meta.id.as_str(), g.cells())
                .unwrap();
        }
        txn.commit().unwrap();
        assert_eq!(store.get(&name, None).unwrap().grid.cells(), g.cells());
    }

    #[test]
    fn unknown_maps_are_named_in_errors() {
        let dir = tempfile::tempdir().unwrap();
        let store = MapStore::open(dir.path()).unwrap();
        let name = MapName::new("nowhere").unwrap();
        let e = store.get(&name, None).unwrap_err().to_string();
        assert!(e.contains("nowhere"), "{e}");
        store.put(&name, &grid(0), &src()).unwrap();
        let e = store.get(&name, Some(7)).unwrap_err().to_string();
        assert!(e.contains("nowhere") && e.contains('7'), "{e}");
        assert!(store
            .versions(&MapName::new("x").unwrap())
            .unwrap()
            .is_empty());
    }

    #[test]
    fn hash_covers_geometry_not_only_cells() {
        let g = grid(0);
        let moved = OccupancyGrid::new(
            40,
            30,
            0.05,
            Pose2D::new(-1.0, 2.0, 0.6),
            g.cells().to_vec(),
        )
        .unwrap();
        let finer = OccupancyGrid::new(40, 30, 0.04, g.origin(), g.cells().to_vec()).unwrap();
        let reshaped = OccupancyGrid::new(30, 40, 0.05, g.origin(), g.cells().to_vec()).unwrap();
        let hashes = [
            content_hash(&g),
            content_hash(&moved),
            content_hash(&finer),
            content_hash(&reshaped),
        ];
        for i in 0..hashes.len() {
            for j in i + 1..hashes.len() {
                assert_ne!(hashes[i], hashes[j]);
            }
        }
    }
}
