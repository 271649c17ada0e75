//! Shards of `.npy` arrays and `index.json`: samples are buffered per field and a shard is
//! written (every file atomically) when it is full or the recording ends.

use std::path::{Path, PathBuf};

use super::episode::Sample;
use super::npy::{self, Dtype};
use super::RecordError;

/// One field of the dataset: its file name, element type and shape per sample.
struct Field {
    name: &'static str,
    dtype: Dtype,
    /// Dimensions after the sample dimension (`None`: the image side).
    tail: &'static [Option<usize>],
    data: Vec<u8>,
}

/// Image fields' per-sample shape: side × side × RGB.
const IMAGE: &[Option<usize>] = &[None, None, Some(3)];

/// Buffers samples and writes shards `shard_NNNNN/<field>.npy` under a folder.
pub struct ShardWriter {
    dir: PathBuf,
    image_px: usize,
    shard_samples: usize,
    fields: Vec<Field>,
    in_shard: usize,
    total: usize,
    shards: Vec<serde_json::Value>,
}

impl ShardWriter {
    #[must_use]
    pub fn new(dir: &Path, image_px: usize, shard_samples: usize) -> Self {
        let field = |name, dtype, tail| Field {
            name,
            dtype,
            tail,
            data: Vec::new(),
        };
        Self {
            dir: dir.to_path_buf(),
            image_px,
            shard_samples,
            fields: vec![
                field("camera", Dtype::U8, IMAGE),
                field("lpe", Dtype::U8, IMAGE),
                field("dlm", Dtype::U8, &[]),
                field("label", Dtype::F32, &[Some(2)]),
                field("target", Dtype::F32, &[Some(2)]),
                field("executed", Dtype::F32, &[Some(2)]),
                field("pose_true", Dtype::F32, &[Some(3)]),
                field("pose_amcl", Dtype::F32, &[Some(3)]),
                field("scenario", Dtype::U32, &[]),
                field("episode", Dtype::U32, &[]),
                field("noisy", Dtype::U8, &[]),
                field("learner", Dtype::U8, &[]),
                field("t_s", Dtype::F32, &[]),
            ],
            in_shard: 0,
            total: 0,
            shards: Vec::new(),
        }
    }

    /// Samples pushed so far.
    #[must_use]
    pub fn samples(&self) -> usize {
        self.total
    }

    fn shape(&self, f: &Field, n: usize) -> Vec<usize> {
        std::iter::once(n)
            .chain(f.tail.iter().map(|d| d.unwrap_or(self.image_px)))
            .collect()
    }

    /// Adds a sample of episode `episode` on scenario `scenario`; writes the shard when full.
    ///
    /// # Errors
    /// [`RecordError::Write`] when a full shard cannot be written.
    pub fn push(
        &mut self,
        s: &Sample,
        scenario: u32,
        episode: u32,
        noisy: bool,
    ) -> Result<(), RecordError> {
        for f in &mut self.fields {
            match f.name {
                "camera" => f.data.extend_from_slice(&s.camera),
                "lpe" => f.data.extend_from_slice(&s.lpe),
                "dlm" => f.data.push(s.dlm),
                "label" => npy::push_f32(&mut f.data, &s.label),
                "target" => npy::push_f32(&mut f.data, &s.target),
                "executed" => npy::push_f32(&mut f.data, &s.executed),
                "pose_true" => npy::push_f32(&mut f.data, &s.pose_true),
                "pose_amcl" => npy::push_f32(&mut f.data, &s.pose_amcl),
                "scenario" => npy::push_u32(&mut f.data, &[scenario]),
                "episode" => npy::push_u32(&mut f.data, &[episode]),
                "noisy" => f.data.push(u8::from(noisy)),
                "learner" => f.data.push(u8::from(s.learner_drove)),
                _ => npy::push_f32(&mut f.data, &[s.t_s]),
            }
        }
        self.in_shard += 1;
        self.total += 1;
        if self.in_shard >= self.shard_samples {
            self.flush()?;
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<(), RecordError> {
        if self.in_shard == 0 {
            return Ok(());
        }
        let name = format!("shard_{:05}", self.shards.len());
        let dir = self.dir.join(&name);
        std::fs::create_dir_all(&dir).map_err(|e| RecordError::Write {
            path: dir.clone(),
            reason: e.to_string(),
        })?;
        let mut files = serde_json::Map::new();
        for i in 0..self.fields.len() {
            let shape = self.shape(&self.fields[i], self.in_shard);
            let f = &mut self.fields[i];
            let bytes = npy::file(f.dtype, &shape, &f.data);
            f.data.clear();
            let file = format!("{name}/{}.npy", f.name);
            let path = self.dir.join(&file);
            map_core::export::write_atomic(&path, &bytes).map_err(|e| RecordError::Write {
                path,
                reason: e.to_string(),
            })?;
            files.insert(f.name.to_string(), file.into());
        }
        self.shards.push(serde_json::json!({
            "name": name,
            "samples": self.in_shard,
            "files": files,
        }));
        self.in_shard = 0;
        Ok(())
    }

    /// Writes the last shard and `index.json` (`header` plus the shards, fields and count);
    /// returns the number of shards.
    ///
    /// # Errors
    /// [`RecordError::Write`].
    pub fn finish(&mut self, header: &serde_json::Value) -> Result<usize, RecordError> {
        self.flush()?;
        let mut index = header.clone();
        let fields: serde_json::Map<String, serde_json::Value> = self
            .fields
            .iter()
            .map(|f| {
                let shape = self.shape(f, 0)[1..].to_vec();
                (
                    f.name.to_string(),
                    serde_json::json!({ "dtype": f.dtype.name(), "shape": shape }),
                )
            })
            .collect();
        if let Some(obj) = index.as_object_mut() {
            obj.insert("samples".into(), self.total.into());
            obj.insert("fields".into(), fields.into());
            obj.insert("shards".into(), self.shards.clone().into());
        }
        let path = self.dir.join("index.json");
        let text = serde_json::to_string_pretty(&index).map_err(|e| RecordError::Write {
            path: path.clone(),
            reason: e.to_string(),
        })?;
        map_core::export::write_atomic(&path, format!("{text}\n").as_bytes()).map_err(|e| {
            RecordError::Write {
                path,
                reason: e.to_string(),
            }
        })?;
        Ok(self.shards.len())
    }
}
