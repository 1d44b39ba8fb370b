//! Products derived from waveforms (section 2.5), a room each:
//! - `returns`: the decomposition of a waveform into discrete returns;
//! - `points`: the returns as points, LAS/LAZ, their spill file and their distance to the
//!   scene's surfaces;
//! - `photons`: photon-counting events;
//! - `raster`: the DSM against the scene's reference, as GeoTIFF and figures;
//! - `mission`: the HDF5 files shaped like the missions' (GEDI L1B, ICESat-2 ATL03);
//! - `figures`: drawing (fonts, line plots, the points from above, waveforms);
//! - `report`: `products.json` and `report.md`;
//! - `stage`: the products stage, a list of writers fed the waveforms a part at a time.

pub mod figures;
pub mod mission;
pub mod photons;
pub mod points;
pub mod raster;
pub mod report;
pub mod returns;
pub mod stage;
