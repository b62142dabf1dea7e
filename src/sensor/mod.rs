//! The image sensor model: spectral irradiance → electrons → volts → digital values.
