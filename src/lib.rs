//! lidarsim: a physically based LiDAR simulator.
//!
//! The modules follow the data's way through the program, each knowing only those before it:
//! campaign → scene → sensor → plan → transport → waveform → products → pipeline → cli.

pub mod error;
pub mod fsutil;
pub mod interrupt;
pub mod parquet_io;
pub mod progress;
pub mod rng;

pub mod bench;
pub mod campaign;
pub mod cli;
pub mod compare;
pub mod generate;
pub mod pipeline;
pub mod plan;
pub mod products;
pub mod scene;
pub mod sensor;
#[doc(hidden)]
pub mod testdata;
pub mod transport;
pub mod waveform;

pub use error::{Error, Result};

/// This build's version, as `lidarsim --version` and run manifests give it.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// Speed of light in vacuum, m/s.
pub const C: f64 = 299_792_458.0;
/// Planck constant, J s.
pub const PLANCK: f64 = 6.626_070_15e-34;

/// Photon energy hν = h c / λ, J, for a wavelength in nm.
pub fn photon_energy_j(wavelength_nm: f64) -> f64 {
    PLANCK * C / (wavelength_nm * 1e-9)
}
