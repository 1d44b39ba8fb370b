//! HDF5 files in the format of HDF5 1.8 (superblock 2, contiguous datasets, data layout 3),
//! which every reader of the missions' files opens, SlideRule's h5coro among them (it reads
//! neither superblock 3 nor layout 4, which chunked and extendable datasets need).
//!
//! A contiguous dataset is written whole, so the rows of a run are kept in a spool file beside
//! the output as they stream by (memory holds at most [`BLOCK`] elements per dataset) and
//! the file is written at [`H5Writer::finish`], one dataset at a time: memory then holds the
//! largest dataset once. Pure Rust (`hdf5-pure`): no libhdf5 to install.

use crate::error::{Error, Result};
use crate::fsutil::{Pending, WRITE_ADVICE};
use hdf5_pure::{AttrValue, DatasetBuilder, File, FileBuilder, LibVer};
use std::collections::HashMap;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Elements per block a dataset's rows are spooled in.
pub const BLOCK: usize = 16_384;

/// The element type of a dataset.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kind {
    F64,
    F32,
    U64,
    U32,
    U16,
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
            Kind::U16 | Kind::I16 => 2,
            Kind::U8 | Kind::I8 => 1,
        }
    }
}

/// A dataset to create: its path from the root, element type, row width (1: rank 1, else
/// rows x `width`), units and meaning (the `units` and `description` attributes, as the
/// mission products carry them), and any other attributes.
pub struct Field<'a> {
    pub path: String,
    pub kind: Kind,
    pub width: usize,
    pub units: &'a str,
    pub description: &'a str,
    pub attrs: Vec<(&'static str, AttrValue)>,
}

impl<'a> Field<'a> {
    /// Rank-1 dataset `name` in `group`.
    pub fn new(group: &str, name: &str, kind: Kind, units: &'a str, description: &'a str) -> Self {
        Field {
            path: format!("{group}/{name}"),
            kind,
            width: 1,
            units,
            description,
            attrs: Vec::new(),
        }
    }

    /// Rows of `width` elements (a rank-2 dataset).
    pub fn rows_of(mut self, width: usize) -> Self {
        self.width = width.max(1);
        self
    }

    /// The `long_name` attribute: the real product's short title of the dataset.
    pub fn long_name(mut self, name: &str) -> Self {
        self.attrs
            .push(("long_name", AttrValue::String(name.to_string())));
        self
    }

    /// The real product's `contentType` (its data dictionary's class of the dataset:
    /// physicalMeasurement, modelResult, referenceInformation, qualityInformation) and its
    /// `coordinates` (the CF attribute naming the variables that locate each element, which
    /// xarray makes the dataset's coordinates; none when empty).
    pub fn cf(mut self, content_type: &str, coordinates: &str) -> Self {
        self.attrs
            .push(("contentType", AttrValue::String(content_type.to_string())));
        if !coordinates.is_empty() {
            self.attrs
                .push(("coordinates", AttrValue::String(coordinates.to_string())));
        }
        self
    }

    /// The product's fill value for the elements the simulation does not define, in the
    /// `_FillValue` attribute (as netCDF and the missions' readers look for it).
    pub fn fill(mut self, value: AttrValue) -> Self {
        self.attrs.push(("_FillValue", value));
        self
    }
}

/// A dataset's rows so far: the last block's little-endian bytes in memory, the blocks
/// before it in the spool as (offset, length).
struct Column {
    path: String,
    kind: Kind,
    width: usize,
    attrs: Vec<(String, AttrValue)>,
    bytes: Vec<u8>,
    spooled: Vec<(u64, usize)>,
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
little_endian!(f64, f32, u64, u32, u16, i64, i32, i16, i8);

/// The little-endian bytes of `v`, element after element.
fn le_bytes<T: LittleEndian>(v: &[T]) -> Vec<u8> {
    let mut out = Vec::with_capacity(std::mem::size_of_val(v));
    for &x in v {
        x.extend_le(&mut out);
    }
    out
}

/// Elements of `N` bytes decoded from little-endian `bytes`.
fn decode<T, const N: usize>(bytes: &[u8], from: fn([u8; N]) -> T) -> Vec<T> {
    bytes
        .chunks_exact(N)
        .map(|c| from(c.try_into().unwrap_or([0; N])))
        .collect()
}

/// Writes one file: groups and datasets are declared as the run meets them, rows appended as
/// they come; nothing is under the final name until [`H5Writer::finish`].
pub struct H5Writer {
    path: PathBuf,
    pending: Pending,
    spool_pending: Pending,
    spool: std::fs::File,
    spool_len: u64,
    root_attrs: Vec<(String, AttrValue)>,
    groups: Vec<(String, Vec<(String, AttrValue)>)>,
    columns: Vec<Column>,
    index: HashMap<String, usize>,
    /// Text attributes of the root and groups as GEDI's files store them: one-element arrays
    /// of variable-length strings (so `attrs["short_name"][0]` reads on ours as on theirs),
    /// rather than fixed-width scalars.
    gedi_strings: bool,
}

/// A text attribute: a fixed-width scalar, or as GEDI stores its text (a one-element array of
/// variable-length ASCII strings, UTF-8 where the text is not ASCII).
fn text_attr(value: &str, gedi: bool) -> AttrValue {
    match (gedi, value.is_ascii()) {
        (false, _) => AttrValue::String(value.to_string()),
        (true, true) => AttrValue::VarLenAsciiStringArray(vec![value.to_string()]),
        (true, false) => AttrValue::VarLenStringArray(vec![value.to_string()]),
    }
}

/// A write the HDF5 writer could not make: the system's refusal, as far as lidarsim can
/// tell (the file is its own, written afresh).
fn h5_error(path: &Path, what: &str, e: hdf5_pure::Error) -> Error {
    Error::io(path, what, std::io::Error::other(e.to_string())).advise(WRITE_ADVICE)
}

impl H5Writer {
    /// A new file with the root attributes `attrs`.
    pub fn create(path: &Path, attrs: &[(&str, String)]) -> Result<H5Writer> {
        let pending = Pending::new(path, "")?;
        let spool_pending = Pending::new(path, ".spool")?;
        let spool = std::fs::File::options()
            .create(true)
            .truncate(true)
            .read(true)
            .write(true)
            .open(spool_pending.tmp())
            .map_err(|e| {
                Error::io(spool_pending.tmp(), "cannot create file", e).advise(WRITE_ADVICE)
            })?;
        Ok(H5Writer {
            path: path.to_path_buf(),
            pending,
            spool_pending,
            spool,
            spool_len: 0,
            root_attrs: attrs
                .iter()
                .map(|(k, v)| (k.to_string(), AttrValue::String(v.clone())))
                .collect(),
            groups: Vec::new(),
            columns: Vec::new(),
            index: HashMap::new(),
            gedi_strings: false,
        })
    }

    /// From here on (and for the root's), text attributes as GEDI's files store them.
    pub fn gedi_strings(&mut self) {
        self.gedi_strings = true;
        for (_, v) in &mut self.root_attrs {
            if let AttrValue::String(s) = v {
                *v = text_attr(s, true);
            }
        }
    }

    /// Declares a group (after its parent) with string attributes.
    pub fn group(&mut self, name: &str, attrs: &[(&str, String)]) -> Result<()> {
        let attrs = attrs
            .iter()
            .map(|(k, v)| (k.to_string(), text_attr(v, self.gedi_strings)))
            .collect();
        self.group_with(name, attrs)
    }

    /// Declares a group with attributes of any type.
    pub fn group_with(&mut self, name: &str, attrs: Vec<(String, AttrValue)>) -> Result<()> {
        self.groups.push((name.to_string(), attrs));
        Ok(())
    }

    /// Declares datasets, appended to by the `push_*` methods.
    pub fn datasets(&mut self, fields: &[Field]) -> Result<()> {
        for f in fields {
            let mut attrs = vec![
                ("units".to_string(), AttrValue::String(f.units.to_string())),
                (
                    "description".to_string(),
                    AttrValue::String(f.description.to_string()),
                ),
            ];
            attrs.extend(f.attrs.iter().map(|(k, v)| (k.to_string(), v.clone())));
            self.index.insert(f.path.clone(), self.columns.len());
            self.columns.push(Column {
                path: f.path.clone(),
                kind: f.kind,
                width: f.width,
                attrs,
                bytes: Vec::new(),
                spooled: Vec::new(),
            });
        }
        Ok(())
    }

    /// Appends little-endian element bytes to dataset `path`; whole blocks go to the spool.
    pub fn push(&mut self, path: &str, bytes: &[u8]) -> Result<()> {
        let &i = self
            .index
            .get(path)
            .ok_or_else(|| Error::msg(format!("{}: no dataset {path}", self.path.display())))?;
        let column = &mut self.columns[i];
        column.bytes.extend_from_slice(bytes);
        if column.bytes.len() >= column.kind.size() * BLOCK {
            let block = std::mem::take(&mut column.bytes);
            self.spool.write_all(&block).map_err(|e| {
                Error::io(self.spool_pending.tmp(), "cannot write", e).advise(WRITE_ADVICE)
            })?;
            column.spooled.push((self.spool_len, block.len()));
            self.spool_len += block.len() as u64;
        }
        Ok(())
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

    pub fn push_u16(&mut self, path: &str, v: &[u16]) -> Result<()> {
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
        self.push(path, &le_bytes(v))
    }

    /// A column's bytes, read back from the spool.
    fn gather(&mut self, i: usize) -> Result<Vec<u8>> {
        let column = &mut self.columns[i];
        let total: usize = column.spooled.iter().map(|s| s.1).sum::<usize>() + column.bytes.len();
        let mut out = Vec::with_capacity(total);
        for &(at, len) in &column.spooled {
            let start = out.len();
            out.resize(start + len, 0);
            self.spool
                .seek(SeekFrom::Start(at))
                .and_then(|_| self.spool.read_exact(&mut out[start..]))
                .map_err(|e| {
                    Error::io(self.spool_pending.tmp(), "cannot read back", e).advise(WRITE_ADVICE)
                })?;
        }
        out.extend_from_slice(&std::mem::take(&mut column.bytes));
        Ok(out)
    }

    /// Writes the file (groups, then each dataset whole) and moves it to its final name.
    pub fn finish(mut self) -> Result<()> {
        let path = self.path.clone();
        let mut builder = FileBuilder::new();
        builder.with_libver_bounds(LibVer::Earliest, LibVer::V18);
        for (name, value) in &self.root_attrs {
            builder.set_attr(name, value.clone());
        }
        builder
            .write(self.pending.tmp())
            .map_err(|e| h5_error(&path, "cannot create HDF5 file", e))?;
        let file = File::open_rw(self.pending.tmp())
            .map_err(|e| h5_error(&path, "cannot open HDF5 file for writing", e))?;
        for (name, attrs) in &self.groups {
            let g = file
                .root()
                .create_group(name)
                .map_err(|e| h5_error(&path, &format!("cannot create group {name}"), e))?;
            for (k, v) in attrs {
                g.set_attr(k, v.clone())
                    .map_err(|e| h5_error(&path, &format!("cannot set {name}/@{k}"), e))?;
            }
            drop(g);
            file.commit()
                .map_err(|e| h5_error(&path, "cannot commit groups", e))?;
        }
        for i in 0..self.columns.len() {
            let bytes = self.gather(i)?;
            let c = &self.columns[i];
            let elements = bytes.len() / c.kind.size();
            let shape = if c.width == 1 {
                vec![elements as u64]
            } else {
                vec![(elements / c.width) as u64, c.width as u64]
            };
            file.root()
                .create_dataset(&c.path, |b| {
                    typed(b, c.kind, &bytes);
                    b.with_shape(&shape);
                    for (k, v) in &c.attrs {
                        b.set_attr(k, v.clone());
                    }
                })
                .map_err(|e| h5_error(&path, &format!("cannot create {}", c.path), e))?;
            file.commit()
                .map_err(|e| h5_error(&path, &format!("cannot write {}", c.path), e))?;
        }
        file.close()
            .map_err(|e| h5_error(&path, "cannot close HDF5 file", e))?;
        self.pending.commit()
    }
}

/// Sets a dataset's type and elements from little-endian bytes.
fn typed(b: &mut DatasetBuilder, kind: Kind, bytes: &[u8]) {
    match kind {
        Kind::F64 => b.with_f64_data(&decode(bytes, f64::from_le_bytes)),
        Kind::F32 => b.with_f32_data(&decode(bytes, f32::from_le_bytes)),
        Kind::U64 => b.with_u64_data(&decode(bytes, u64::from_le_bytes)),
        Kind::U32 => b.with_u32_data(&decode(bytes, u32::from_le_bytes)),
        Kind::U16 => b.with_u16_data(&decode(bytes, u16::from_le_bytes)),
        Kind::U8 => b.with_u8_data(bytes),
        Kind::I8 => b.with_i8_data(&decode(bytes, i8::from_le_bytes)),
        Kind::I16 => b.with_i16_data(&decode(bytes, i16::from_le_bytes)),
        Kind::I32 => b.with_i32_data(&decode(bytes, i32::from_le_bytes)),
        Kind::I64 => b.with_i64_data(&decode(bytes, i64::from_le_bytes)),
    };
}
