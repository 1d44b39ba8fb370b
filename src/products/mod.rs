//! Products derived from waveforms (section 2.5): discrete returns and their points, the
//! LAS file, and photon-counting events.

pub mod accuracy;
pub mod dsm;
pub mod figures;
pub mod h5;
pub mod las;
pub mod mission;
pub mod photons;
pub mod plot;
pub mod points;
pub mod report;
pub mod returns;
pub mod spill;
pub mod stage;
pub mod summary;
