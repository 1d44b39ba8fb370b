//! Products derived from waveforms: discrete returns, LAS, photon counts, DSM error.
//! (Nothing yet: the single-pulse foundation writes waveforms only.)
