//! Measurements, one module each: slanted-edge SFR, relative illumination,
//! uniform-region noise, line profiles, MCC patch means, comparisons.
