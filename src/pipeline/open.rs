//! A run folder read back as tables: what the Python package's `open_run` hands over, and
//! what scripts read instead of parsing the files themselves (outputs.md is the contract of
//! the files; these are the same columns).

use crate::error::{Error, Result};
use crate::products::raster::geotiff::{self, Raster};
use arrow_array::{Array, BooleanArray, RecordBatch, UInt64Array};
use arrow_schema::SchemaRef;
use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// A table: its schema and its batches (none when it has no rows).
pub type Table = (SchemaRef, Vec<RecordBatch>);

/// A run folder, checked to be one.
#[derive(Clone, Debug)]
pub struct RunFolder {
    pub folder: PathBuf,
}

/// The three DSM rasters of a run.
#[derive(Clone, Debug)]
pub struct DsmRasters {
    pub dsm: Raster,
    pub reference: Raster,
    pub difference: Raster,
}

impl RunFolder {
    /// A folder `lidarsim run` wrote (it holds `manifest.json`).
    pub fn open(folder: &Path) -> Result<RunFolder> {
        if !folder.join("manifest.json").is_file() {
            return Err(Error::file(
                folder,
                "not a run folder: it has no manifest.json; run the campaign first",
            ));
        }
        Ok(RunFolder {
            folder: folder.to_path_buf(),
        })
    }

    fn file(&self, name: &str, stage: &str) -> Result<PathBuf> {
        let p = self.folder.join(name);
        if p.is_file() {
            Ok(p)
        } else {
            Err(Error::file(&p, "does not exist").advise(format!(
                "the {stage} stage writes it: run the campaign (again) with that stage, or \
                 check that the campaign's products ask for it"
            )))
        }
    }

    /// A text file of the folder, whole.
    pub fn text(&self, name: &str, stage: &str) -> Result<String> {
        crate::error::read_text(&self.file(name, stage)?)
    }

    /// `manifest.json`, checked to be a run's manifest (a damaged one is a data error, as
    /// `--resume` and `compare` take it).
    pub fn manifest_json(&self) -> Result<String> {
        let path = self.file("manifest.json", "plan")?;
        let text = crate::error::read_text(&path)?;
        let manifest = serde_json::from_str::<super::manifest::Manifest>(&text);
        match serde_json::from_str::<serde_json::Value>(&text) {
            Ok(v) if v.is_object() && manifest.is_ok() => Ok(text),
            Ok(_) => Err(Error::data(&path, "not a lidarsim manifest")
                .advise("run the campaign again (--resume redoes what it cannot trust)")),
            Err(e) => Err(Error::data(&path, format!("damaged: {e}"))
                .advise("run the campaign again (--resume redoes what it cannot trust)")),
        }
    }

    /// `campaign.resolved.yaml`, parsed (its keys that are numbers stay numbers: a band's
    /// `532.0` of an optical depth's table).
    pub fn campaign(&self) -> Result<serde_yaml::Value> {
        let path = self.file("campaign.resolved.yaml", "plan")?;
        let text = crate::error::read_text(&path)?;
        match serde_yaml::from_str::<serde_yaml::Value>(&text) {
            Ok(v) if v.is_mapping() => Ok(v),
            Ok(_) => Err(Error::data(&path, "damaged: not a resolved campaign")
                .advise("run the campaign again with --resume: its plan stage writes it")),
            Err(e) => Err(Error::data(&path, format!("not YAML: {e}"))
                .advise("run the campaign again with --resume: its plan stage writes it")),
        }
    }

    /// `pulses.parquet`.
    pub fn pulses(&self) -> Result<Table> {
        crate::parquet_io::read_batches(&self.file("pulses.parquet", "plan")?, None)
    }

    /// The rows of every waveform part, in part order; only the rows of `pulse_ids` when
    /// given (one row per pulse and band).
    pub fn waveforms(&self, pulse_ids: Option<&[u64]>) -> Result<Table> {
        let dir = self.folder.join("waveforms");
        let mut parts: Vec<PathBuf> = std::fs::read_dir(&dir)
            .map_err(|e| {
                if dir.exists() {
                    Error::io(&dir, "cannot list the waveform parts", e)
                } else {
                    Error::file(&dir, "does not exist")
                }
                .advise("the simulate stage writes them: run the campaign")
            })?
            .flatten()
            .map(|e| e.path())
            .filter(|p| {
                p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with("part-") && n.ends_with(".parquet"))
            })
            .collect();
        parts.sort();
        let wanted: Option<HashSet<u64>> = pulse_ids.map(|ids| ids.iter().copied().collect());
        let keep = |b: &RecordBatch| -> Option<BooleanArray> {
            let wanted = wanted.as_ref()?;
            let ids = b.column_by_name("pulse_id")?;
            let ids = ids.as_any().downcast_ref::<UInt64Array>()?;
            Some(
                (0..ids.len())
                    .map(|i| Some(ids.is_valid(i) && wanted.contains(&ids.value(i))))
                    .collect(),
            )
        };
        let mut schema = None;
        let mut batches = Vec::new();
        for p in &parts {
            if !crate::waveform::file::part_matches_checksum(p) {
                return Err(Error::data(
                    p,
                    format!(
                        "damaged or unfinished: its bytes are not those {} records",
                        crate::waveform::file::checksum_path(p)
                            .file_name()
                            .unwrap_or_default()
                            .to_string_lossy()
                    ),
                )
                .advise("run the campaign again with --resume: it simulates such parts again"));
            }
            let (s, b) = crate::parquet_io::read_batches(p, Some(&keep))?;
            if schema.as_ref().is_some_and(|known: &SchemaRef| known != &s) {
                return Err(Error::data(p, "its columns differ from the other parts'")
                    .advise("run the simulate stage again"));
            }
            schema.get_or_insert(s);
            batches.extend(b);
        }
        let schema = schema.ok_or_else(|| {
            Error::file(&dir, "holds no waveform parts")
                .advise("the simulate stage writes them: run the campaign")
        })?;
        Ok((schema, batches))
    }

    /// `points.las` or `points.laz`, one row per point ([`crate::products::points::points_table`]).
    pub fn points(&self) -> Result<RecordBatch> {
        let path = ["points.las", "points.laz"]
            .iter()
            .map(|n| self.folder.join(n))
            .find(|p| p.is_file())
            .ok_or_else(|| {
                Error::file(&self.folder.join("points.las"), "does not exist").advise(
                    "the products stage writes points for discrete-return instruments, or \
                     with `products: { points: true }`",
                )
            })?;
        let points = crate::products::points::las::read_las(&path)?;
        Ok(crate::products::points::points_table(&points))
    }

    /// `photons.parquet`.
    pub fn photons(&self) -> Result<Table> {
        crate::parquet_io::read_batches(&self.file("photons.parquet", "products")?, None)
    }

    /// `dsm/dsm.tif`, `dsm/reference.tif` and `dsm/difference.tif`.
    pub fn dsm(&self) -> Result<DsmRasters> {
        let read = |name: &str| geotiff::read(&self.file(&format!("dsm/{name}.tif"), "products")?);
        Ok(DsmRasters {
            dsm: read("dsm")?,
            reference: read("reference")?,
            difference: read("difference")?,
        })
    }
}
