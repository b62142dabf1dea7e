//! Colour conversions: CIE XYZ ↔ linear sRGB (D65 white, IEC 61966-2-1), sRGB
//! encoding, and reflectance → display colour under D65.

use super::{Spectrum, WavelengthGrid, library, xyz};

/// XYZ (Y = 1 white) → linear sRGB.
pub fn xyz_to_linear_srgb(c: [f64; 3]) -> [f64; 3] {
    let [x, y, z] = c;
    [
        3.2404542 * x - 1.5371385 * y - 0.4985314 * z,
        -0.9692660 * x + 1.8760108 * y + 0.0415560 * z,
        0.0556434 * x - 0.2040259 * y + 1.0572252 * z,
    ]
}

/// Linear value → sRGB-encoded value in [0, 1].
pub fn srgb_encode(v: f64) -> f64 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.0031308 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Linear sRGB of a reflectance lit by CIE D65, normalised so a perfect white is (1,1,1)-ish (Y = 1).
pub fn reflectance_to_linear_srgb(r: &Spectrum) -> [f64; 3] {
    let grid = WavelengthGrid::new(380.0, 780.0, 5.0).expect("valid grid");
    let d65 = library::named("cie-d65").expect("shipped");
    let white_y = xyz(&d65, &grid)[1];
    let lit = Spectrum::new(
        "lit",
        grid.wavelengths(),
        grid.wavelengths()
            .iter()
            .map(|&l| r.eval(l) * d65.eval(l))
            .collect(),
    )
    .expect("finite");
    let c = xyz(&lit, &grid);
    xyz_to_linear_srgb([c[0] / white_y, c[1] / white_y, c[2] / white_y])
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn white_reflector_is_neutral_white() {
        let c = reflectance_to_linear_srgb(&Spectrum::constant("one", 1.0));
        // D65 is sRGB's white point: a perfect reflector maps to (1,1,1) within table rounding.
        for v in c {
            assert!((v - 1.0).abs() < 0.01, "{c:?}");
        }
    }
}
