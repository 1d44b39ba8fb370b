//! HDF5 files written as the parts stream by: each dataset is created empty and extendable,
//! then appended to a chunk at a time, so memory holds at most a chunk per dataset whatever
//! the campaign's length. Pure Rust (`hdf5-pure`): no libhdf5 to install.

use crate::error::{Error, Result};
use crate::fsutil::Pending;
use hdf5_pure::{AttrValue, File, FileAccessProperties, FileBuilder, MaxExtent, SyncPolicy};
use std::collections::BTreeMap;
use std::path::Path;

/// Elements per chunk, and per append: the unit of what is held in memory per dataset.
pub const CHUNK: usize = 16_384;

/// The element type of a dataset.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kind {
    F64,
    F32,
    U64,
    U32,
    U8,
    I8,
    I16,
    I32,
    I64,
}

impl Kind {
    fn size(self) -> usize {
        match self {
            Kind::F64 | Kind::U64 | Kind::I64 => 8,
            Kind::F32 | Kind::U32 | Kind::I32 => 4,
            Kind::U8 | Kind::I8 => 1,
            Kind::I16 => 2,
        }
    }
}

/// A rank-1 dataset to create: its path from the root, element type, units and meaning (the
/// `units` and `description` attributes, as the mission products carry them).
pub struct Field<'a> {
    pub path: String,
    pub kind: Kind,
    pub units: &'a str,
    pub description: &'a str,
}

impl<'a> Field<'a> {
    /// Dataset `name` in `group`.
    pub fn new(group: &str, name: &str, kind: Kind, units: &'a str, description: &'a str) -> Self {
        Field {
            path: format!("{group}/{name}"),
            kind,
            units,
            description,
        }
    }
}

/// A column's elements not yet in the file, as little-endian bytes.
struct Column {
    size: usize,
    bytes: Vec<u8>,
}

/// A number's little-endian bytes, as HDF5's little-endian types store it.
trait LittleEndian: Copy {
    fn extend_le(self, out: &mut Vec<u8>);
}

macro_rules! little_endian {
    ($($t:ty),*) => {$(
        impl LittleEndian for $t {
            fn extend_le(self, out: &mut Vec<u8>) {
                out.extend_from_slice(&self.to_le_bytes());
            }
        }
    )*};
}
little_endian!(f64, f32, u64, u32, i64, i32, i16);

/// The little-endian bytes of `v`, element after element.
fn le_bytes<T: LittleEndian>(v: &[T]) -> Vec<u8> {
    let mut out = Vec::with_capacity(std::mem::size_of_val(v));
    for &x in v {
        x.extend_le(&mut out);
    }
    out
}

/// Fields drop in order: the HDF5 session closes before `pending` removes an unfinished file.
pub struct H5Writer {
    file: Option<File>,
    pending: Pending,
    columns: BTreeMap<String, Column>,
    path: std::path::PathBuf,
}

/// A write the HDF5 writer could not make: the system's refusal, as far as lidarsim can
/// tell (the file is its own, written afresh).
fn h5_error(path: &Path, what: &str, e: hdf5_pure::Error) -> Error {
    Error::io(path, what, std::io::Error::other(e.to_string())).advise(crate::fsutil::WRITE_ADVICE)
}

impl H5Writer {
    /// A new file under its temporary name, with the root attributes `attrs`.
    pub fn create(path: &Path, attrs: &[(&str, String)]) -> Result<H5Writer> {
        let pending = Pending::new(path, "")?;
        let mut builder = FileBuilder::new();
        for (name, value) in attrs {
            builder.set_attr(name, AttrValue::String(value.clone()));
        }
        builder
            .write(pending.tmp())
            .map_err(|e| h5_error(path, "cannot create HDF5 file", e))?;
        let access = FileAccessProperties::new().with_sync_policy(SyncPolicy::OnClose);
        let file = File::open_rw_with_options(pending.tmp(), access)
            .map_err(|e| h5_error(path, "cannot open HDF5 file for writing", e))?;
        Ok(H5Writer {
            file: Some(file),
            pending,
            columns: BTreeMap::new(),
            path: path.to_path_buf(),
        })
    }

    fn file(&self) -> Result<&File> {
        self.file
            .as_ref()
            .ok_or_else(|| Error::msg(format!("{}: HDF5 file closed", self.path.display())))
    }

    /// Creates a group (its parents must exist) with string attributes.
    pub fn group(&mut self, name: &str, attrs: &[(&str, String)]) -> Result<()> {
        let path = self.path.clone();
        let file = self.file()?;
        let g = file
            .root()
            .create_group(name)
            .map_err(|e| h5_error(&path, &format!("cannot create group {name}"), e))?;
        for (k, v) in attrs {
            g.set_attr(k, AttrValue::String(v.clone()))
                .map_err(|e| h5_error(&path, &format!("cannot set {name}/@{k}"), e))?;
        }
        drop(g);
        file.commit()
            .map_err(|e| h5_error(&path, "cannot commit groups", e))
    }

    /// Creates empty extendable datasets, appended to by [`H5Writer::push`].
    pub fn datasets(&mut self, fields: &[Field]) -> Result<()> {
        let path = self.path.clone();
        let file = self.file()?;
        for f in fields {
            file.root()
                .create_dataset(&f.path, |b| {
                    match f.kind {
                        Kind::F64 => b.with_f64_data(&[]),
                        Kind::F32 => b.with_f32_data(&[]),
                        Kind::U64 => b.with_u64_data(&[]),
                        Kind::U32 => b.with_u32_data(&[]),
                        Kind::U8 => b.with_u8_data(&[]),
                        Kind::I8 => b.with_i8_data(&[]),
                        Kind::I16 => b.with_i16_data(&[]),
                        Kind::I32 => b.with_i32_data(&[]),
                        Kind::I64 => b.with_i64_data(&[]),
                    };
                    b.with_shape(&[0])
                        .with_maxshape(&[MaxExtent::Unlimited])
                        .with_chunks(&[CHUNK as u64])
                        .with_deflate(1);
                    b.set_attr("units", AttrValue::String(f.units.to_string()));
                    b.set_attr("description", AttrValue::String(f.description.to_string()));
                })
                .map_err(|e| h5_error(&path, &format!("cannot create {}", f.path), e))?;
        }
        file.commit()
            .map_err(|e| h5_error(&path, "cannot commit datasets", e))?;
        for f in fields {
            self.columns.insert(
                f.path.clone(),
                Column {
                    size: f.kind.size(),
                    bytes: Vec::new(),
                },
            );
        }
        Ok(())
    }

    /// Appends little-endian element bytes to dataset `path`, writing whole chunks through.
    pub fn push(&mut self, path: &str, bytes: &[u8]) -> Result<()> {
        let column = self
            .columns
            .get_mut(path)
            .ok_or_else(|| Error::msg(format!("{}: no dataset {path}", self.path.display())))?;
        column.bytes.extend_from_slice(bytes);
        let whole = column.bytes.len() / (column.size * CHUNK) * (column.size * CHUNK);
        if whole > 0 {
            let rest = column.bytes.split_off(whole);
            let done = std::mem::replace(&mut column.bytes, rest);
            self.append(path, &done)?;
        }
        Ok(())
    }

    fn append(&self, path: &str, bytes: &[u8]) -> Result<()> {
        let mut ds = self
            .file()?
            .dataset(path)
            .map_err(|e| h5_error(&self.path, &format!("cannot open {path}"), e))?;
        ds.append_raw(bytes)
            .map_err(|e| h5_error(&self.path, &format!("cannot append to {path}"), e))
    }

    pub fn push_f64(&mut self, path: &str, v: &[f64]) -> Result<()> {
        self.push(path, &le_bytes(v))
    }

    pub fn push_f32(&mut self, path: &str, v: &[f32]) -> Result<()> {
        self.push(path, &le_bytes(v))
    }

    pub fn push_u64(&mut self, path: &str, v: &[u64]) -> Result<()> {
        self.push(path, &le_bytes(v))
    }

    pub fn push_u32(&mut self, path: &str, v: &[u32]) -> Result<()> {
        self.push(path, &le_bytes(v))
    }

    pub fn push_i32(&mut self, path: &str, v: &[i32]) -> Result<()> {
        self.push(path, &le_bytes(v))
    }

    pub fn push_i64(&mut self, path: &str, v: &[i64]) -> Result<()> {
        self.push(path, &le_bytes(v))
    }

    pub fn push_i16(&mut self, path: &str, v: &[i16]) -> Result<()> {
        self.push(path, &le_bytes(v))
    }

    pub fn push_u8(&mut self, path: &str, v: &[u8]) -> Result<()> {
        self.push(path, v)
    }

    pub fn push_i8(&mut self, path: &str, v: &[i8]) -> Result<()> {
        self.push(path, &v.iter().map(|&x| x as u8).collect::<Vec<u8>>())
    }

    /// Writes a whole dataset of `rows` x `cols` i8 at once (for the few datasets of rank 2,
    /// which the crate cannot append to).
    pub fn matrix_i8(&mut self, f: &Field, rows: usize, cols: usize, v: &[i8]) -> Result<()> {
        let path = self.path.clone();
        let file = self.file()?;
        file.root()
            .create_dataset(&f.path, |b| {
                b.with_i8_data(v)
                    .with_shape(&[rows as u64, cols as u64])
                    .with_chunks(&[CHUNK.min(rows.max(1)) as u64, cols as u64])
                    .with_deflate(1);
                b.set_attr("units", AttrValue::String(f.units.to_string()));
                b.set_attr("description", AttrValue::String(f.description.to_string()));
            })
            .map_err(|e| h5_error(&path, &format!("cannot create {}", f.path), e))?;
        file.commit()
            .map_err(|e| h5_error(&path, &format!("cannot commit {}", f.path), e))
    }

    /// Writes what is buffered, closes the file and moves it to its final name.
    pub fn finish(mut self) -> Result<()> {
        for (p, column) in std::mem::take(&mut self.columns) {
            if !column.bytes.is_empty() {
                self.append(&p, &column.bytes)?;
            }
        }
        if let Some(file) = self.file.take() {
            file.close()
                .map_err(|e| h5_error(&self.path, "cannot close HDF5 file", e))?;
        }
        self.pending.commit()
    }
}
