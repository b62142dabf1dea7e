//! Parameter-reach probe of the `sensor` node (included by tests/params_reach.rs).
//!
//! For every property of `camsim::sensor::SCHEMA`: the value the BUILT
//! `SensorConfig` holds, converted back to the property's KDL unit by this
//! probe's own arithmetic (not by the code under test), so a dropped property
//! or a unit slip in the sensor's setter shows up as a mismatch.

use camsim::params::Value;
use camsim::sensor::SensorConfig;
use camsim::sensor::config::{ConversionGain, Exposure};

/// The held value of property `name` in its KDL unit; None for a name this
/// probe does not know.
pub fn probe(name: &str, cfg: &SensorConfig) -> Option<Value> {
    let n = Value::Number;
    let s = &cfg.sources;
    // Auto-exposure settings exist only while the exposure is automatic; a
    // fixed exposure holds none, said in words so it never equals a number.
    let auto = |pick: fn(f64, f64) -> f64| match cfg.exposure {
        Exposure::Auto { level, percentile } => n(pick(level, percentile)),
        Exposure::Seconds(t) => Value::String(format!("fixed exposure {t} s")),
    };
    // The ADC step, V: voltage swing / 2^bits (ISETCam's convention).
    let step_v = cfg.voltage_swing_v / 2f64.powi(cfg.bit_depth as i32);
    Some(match name {
        "name" => Value::String(cfg.name.clone()),
        "rows" => cfg
            .rows
            .map_or(Value::String("unset".into()), |r| n(r as f64)),
        "cols" => cfg
            .cols
            .map_or(Value::String("unset".into()), |c| n(c as f64)),
        "pixel-size-um" => n(cfg.pixel_size_m * 1e6),
        "fill-factor" => n(cfg.fill_factor),
        "cfa" => {
            // Row by row from the top-left cell of the CFA's repeating tile.
            if cfg.cfa.channels.len() == 1 {
                Value::String("mono".into())
            } else {
                Value::String(
                    cfg.cfa
                        .cells
                        .iter()
                        .map(|&i| cfg.cfa.channels[i as usize].as_str())
                        .collect(),
                )
            }
        }
        "ir-filter" => Value::String(cfg.ir_filter_ref.clone()),
        "well-capacity-e" => n(cfg.well_capacity_e),
        "voltage-swing-v" => n(cfg.voltage_swing_v),
        "conversion-gain-dv-per-e" => match cfg.conversion_gain {
            ConversionGain::DvPerElectron(k) => n(k),
            ConversionGain::VoltsPerElectron(g) => n(g / step_v),
            ConversionGain::FromWell => n(cfg.voltage_swing_v / cfg.well_capacity_e / step_v),
        },
        "conversion-gain-uv-per-e" => match cfg.conversion_gain {
            ConversionGain::VoltsPerElectron(g) => n(g * 1e6),
            ConversionGain::DvPerElectron(k) => n(k * step_v * 1e6),
            ConversionGain::FromWell => n(cfg.voltage_swing_v / cfg.well_capacity_e * 1e6),
        },
        "analog-gain" => n(cfg.analog_gain),
        // ISO 55 is analog gain 1 (ISETCam's IMX363 convention).
        "iso" => n(cfg.analog_gain * 55.0),
        "black-level-dv" => n(cfg.black_level_dv),
        "bit-depth" => n(cfg.bit_depth as f64),
        "exposure-s" => match cfg.exposure {
            Exposure::Seconds(t) => n(t),
            Exposure::Auto { .. } => Value::String("auto".into()),
        },
        "auto-exposure-level" => auto(|l, _| l),
        "auto-exposure-percentile" => auto(|_, p| p),
        "read-noise-mv" => n(cfg.read_noise_v * 1e3),
        "reset-noise-mv" => n(cfg.reset_noise_v * 1e3),
        "dsnu-mv" => n(cfg.dsnu_v * 1e3),
        "prnu-percent" => n(cfg.prnu * 100.0),
        "dark-voltage-mv-per-s" => n(cfg.dark_voltage_v_per_s * 1e3),
        "column-fpn-offset-mv" => n(cfg.column_fpn_offset_v * 1e3),
        "column-fpn-gain-percent" => n(cfg.column_fpn_gain * 100.0),
        "fpn-seed" => n(cfg.fpn_seed as f64),
        "illuminance-scale-factor" => n(cfg.illuminance_scale),
        "photon-noise" => Value::Bool(s.photon_noise),
        "dark-current" => Value::Bool(s.dark_current),
        "dsnu" => Value::Bool(s.dsnu),
        "prnu" => Value::Bool(s.prnu),
        "read-noise" => Value::Bool(s.read_noise),
        "reset-noise" => Value::Bool(s.reset_noise),
        "column-fpn" => Value::Bool(s.column_fpn),
        "pixel-vignetting" => Value::Bool(s.pixel_vignetting),
        "clipping" => Value::Bool(s.clipping),
        "quantization" => Value::Bool(s.quantization),
        _ => return None,
    })
}
